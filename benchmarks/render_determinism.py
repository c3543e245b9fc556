"""How many different images one seeded episode renders in fresh processes: 1 means rendering is deterministic.

    python benchmarks/render_determinism.py [SPEC] [--processes 6] [--steps 12] [--threads 0] [--busy] [--unsorted]

Each process makes the env, resets it with seed 3 and takes ``--steps`` seeded random
actions; it prints the md5 of the linear Combined passes it rendered
(``BlenderRenderer.last_linear_pass``: every bit, where 8-bit observations hide most).
``--busy`` runs a process that keeps a core busy beside them; ``--unsorted`` turns off
:func:`visualenv.compat.blender.sort_faces` (the state before it: bmesh's UV spheres
with their faces in a per-process order), for a before/after.
"""

from __future__ import annotations

import argparse
import hashlib
import subprocess
import sys
from collections import Counter

CHILD = """
import hashlib, sys
import visualenv
import visualenv.compat.blender as compat
if sys.argv[4] == "1":
    compat.sort_faces = lambda bm: None
    import visualenv.render.blender.scene.build as scene, visualenv.render.blender.scene.mjcf as mjcf
    scene.sort_faces = mjcf.sort_faces = compat.sort_faces
env = visualenv.make(sys.argv[1], threads=int(sys.argv[3]))
env.reset(seed=3)
env.action_space.seed(3)
digest = hashlib.md5()
for _ in range(int(sys.argv[2])):
    env.step(env.action_space.sample())
    digest.update(env.unwrapped.renderer.last_linear_pass().tobytes())
print(digest.hexdigest())
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("spec", nargs="?", default="VisualInvertedPendulum-v0")
    parser.add_argument("--processes", type=int, default=6)
    parser.add_argument("--steps", type=int, default=12)
    parser.add_argument("--threads", type=int, default=0, help="render threads (0: every core)")
    parser.add_argument("--busy", action="store_true", help="a process keeps a core busy beside the renders")
    parser.add_argument("--unsorted", action="store_true", help="bmesh's face order as it comes (before sort_faces)")
    args = parser.parse_args()
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"]) if args.busy else None
    try:
        digests = [subprocess.run([sys.executable, "-c", CHILD, args.spec, str(args.steps), str(args.threads), str(int(args.unsorted))],
                                  capture_output=True, text=True, check=True).stdout.split()[-1] for _ in range(args.processes)]
    finally:
        if busy is not None:
            busy.kill()
    counts = Counter(digests)
    print(f"{args.spec}: {args.processes} processes, {args.steps} steps, threads {args.threads}, busy {args.busy}, "
          f"unsorted {args.unsorted}: {len(counts)} different image sequence(s)")
    for digest, n in counts.most_common():
        print(f"  {digest}  x{n}")
    print("digest of all:", hashlib.md5(" ".join(digests).encode()).hexdigest()[:12])


if __name__ == "__main__":
    main()
