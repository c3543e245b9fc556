"""What distractions cost a batch: ms per step and per reset of DMC-cartpole-swingup-v0 (84x84, action repeat 8) in one
batch of N envs, without distractions, with every kind fixed per episode (0.2), with colours and background only (no
camera orbit: no shader compiled again), and with every kind drifting every step. Kinds alternate, each in a fresh
process. A reset draws every env's distraction; a fixed one changes nothing in the steps after it, a dynamic one changes
every env's every step (its camera orbit makes Cycles compile the tiles shader again, as a camera the state turns).
Wall time and this process's CPU time (every thread's: less moved by other processes on a shared machine).

    python benchmarks/batch_distractions.py [N,...] [ROUNDS] [KIND,...]
"""

import statistics
import subprocess
import sys
import time

import numpy as np

KINDS = {
    "none": None,
    "fixed": 0.2,
    "fixed-no-camera": {"difficulty": 0.2, "camera": False},
    "dynamic": {"difficulty": 0.2, "dynamic": True},
}


def one(n: int, kind: str, steps: int = 16, resets: int = 3) -> None:
    import visualenv

    batch = visualenv.make_vec("DMC-cartpole-swingup-v0", n, batched=True, distractions=KINDS[kind])
    rng = np.random.default_rng(0)
    batch.reset(seed=0)
    for _ in range(3):
        batch.step(rng.uniform(-1, 1, (n, 1)).astype(np.float32))
    start, cpu = time.perf_counter(), time.process_time()
    for _ in range(steps):
        batch.step(rng.uniform(-1, 1, (n, 1)).astype(np.float32))
    step_ms, step_cpu = ((time.perf_counter() - start) / steps * 1000, (time.process_time() - cpu) / steps * 1000)
    times, cpus = [], []
    for seed in range(1, resets + 1):
        start, cpu = time.perf_counter(), time.process_time()
        batch.reset(seed=seed)
        times.append((time.perf_counter() - start) * 1000)
        cpus.append((time.process_time() - cpu) * 1000)
    print(f"N={n:>4} {kind:<16}: a step {step_ms:7.1f} ms ({step_cpu:7.1f} ms CPU), a reset {statistics.median(times):7.1f} ms "
          f"({statistics.median(cpus):7.1f} ms CPU)", flush=True)
    batch.close()


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--one":
        one(int(sys.argv[2]), sys.argv[3])
        sys.exit()
    sizes = [int(v) for v in (sys.argv[1] if len(sys.argv) > 1 else "16,64").split(",")]
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 2
    kinds = sys.argv[3].split(",") if len(sys.argv) > 3 else list(KINDS)
    for n in sizes:
        for _ in range(rounds):
            for kind in kinds:
                subprocess.run([sys.executable, __file__, "--one", str(n), kind], check=True)
