"""What a turning camera costs a batch: ms per step of the randomization example's scene, its camera fixed, turned at
resets only (as examples/domain_randomization.yaml), or turned every step (a look_at that follows the box). Each turn
changes the tiles shader's rotation parameters, which Cycles compiles again. Kinds alternate, each in a fresh process.

    python benchmarks/batched_turning.py [N,...] [RESOLUTION] [ROUNDS]
"""

import subprocess
import sys
import time
from pathlib import Path

import numpy as np

EXAMPLE = Path(__file__).parents[1] / "examples" / "domain_randomization.yaml"
CAMERA = "  Camera: {location: [0, -distance, 2], look_at: [0, 0, 0]}\n"
KINDS = {
    "fixed": lambda text: text.replace(CAMERA, ""),
    "at resets": lambda text: text,
    "every step": lambda text: text.replace(CAMERA, CAMERA.replace("look_at: [0, 0, 0]", "look_at: [x, 0, 0]")),
}


def one(n: int, resolution: int, kind: str, steps: int = 20) -> None:
    from visualenv.env.batch import BatchedVectorEnv
    from visualenv.spec import load_spec_text

    text = KINDS[kind](EXAMPLE.read_text().replace("[84, 84]", f"[{resolution}, {resolution}]"))
    if n > 63:  # a bound sun has its own light set per env, at most 63: drop it past that
        text = text.replace("  Sun: {strength: sun}\n", "")
    batch = BatchedVectorEnv(load_spec_text(text, name="turning.yaml"), n)
    batch.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(3):
        batch.step(rng.integers(0, 2, n))
    updates = batch.renderer.shader_updates
    start = time.perf_counter()
    for _ in range(steps):
        batch.step(rng.integers(0, 2, n))
    ms = (time.perf_counter() - start) / steps * 1000
    print(f"N={n:>5} {resolution}x{resolution} camera {kind:<10}: {ms:7.1f} ms a step, {n / ms * 1000:7.0f} env-steps/s, "
          f"{batch.renderer.shader_updates - updates} shader changes in {steps} steps", flush=True)
    batch.close()


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--one":
        one(int(sys.argv[2]), int(sys.argv[3]), sys.argv[4])
        sys.exit()
    sizes = [int(v) for v in (sys.argv[1] if len(sys.argv) > 1 else "16,63").split(",")]
    resolution = int(sys.argv[2]) if len(sys.argv) > 2 else 32
    rounds = int(sys.argv[3]) if len(sys.argv) > 3 else 2
    for n in sizes:
        for _ in range(rounds):
            for kind in KINDS:
                subprocess.run([sys.executable, __file__, "--one", str(n), str(resolution), kind], check=True)
