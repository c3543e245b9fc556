"""What the scene's lights cost a render call: each light's parts turned off in turn, in one process, interleaved.

    python benchmarks/light_cost.py [--rounds 6] [--renders 60] [IDS...]

For each id: the env steps 5 times (its state then stays), and Blender's render call alone (the renderer's
``raw_render``) is timed ``--renders`` times per variant, the variants interleaved in each round: the scene as it
is; its lights hidden; their strength at 1e-4; their node trees off; their shadows off; and every mesh's material a
plain Diffuse BSDF, with the lights and without. Prints the median over rounds of each variant's median call (ms).
Only "as is" draws the env's frames: every other variant changes them, or shows what a part costs.
"""

from __future__ import annotations

import argparse
import os
import time
from typing import Any, Callable

import bpy
import numpy as np

import visualenv

DEFAULT_IDS = ["VisualCartPole-v0", "DMC-cartpole-swingup-v0", "DMC-reacher-easy-v0", "DMC-cheetah-run-v0"]


def variants(scene: Any) -> dict[str, Callable[[bool], None]]:
    """Each variant as a switch: on(True) changes the scene, on(False) puts it back."""
    lights = [o for o in scene.objects if o.type == "LIGHT"]
    meshes = [o for o in scene.objects if o.type == "MESH"]
    energy = {o.name: o.data.energy for o in lights}
    nodes = {o.name: o.data.use_nodes for o in lights}
    shadow = {o.name: o.data.use_shadow for o in lights}
    plain = bpy.data.materials.new("plain diffuse")
    tree = plain.node_tree
    tree.nodes.clear()
    tree.links.new(
        tree.nodes.new("ShaderNodeBsdfDiffuse").outputs[0], tree.nodes.new("ShaderNodeOutputMaterial").inputs[0]
    )
    slots = [(slot, slot.link, slot.material) for o in meshes for slot in o.material_slots]

    def hidden(on: bool) -> None:
        for o in lights:
            o.hide_render = on

    def faint(on: bool) -> None:
        for o in lights:
            o.data.energy = 1e-4 if on else energy[o.name]

    def no_nodes(on: bool) -> None:
        for o in lights:
            o.data.use_nodes = False if on else nodes[o.name]

    def no_shadows(on: bool) -> None:
        for o in lights:
            o.data.use_shadow = False if on else shadow[o.name]

    def diffuse(on: bool) -> None:
        for slot, link, material in slots:
            slot.link, slot.material = ("OBJECT", plain) if on else (link, material)

    def diffuse_unlit(on: bool) -> None:
        diffuse(on)
        hidden(on)

    return {
        "as is": lambda on: None,
        "lights hidden": hidden,
        "strength 1e-4": faint,
        "light nodes off": no_nodes,
        "shadows off": no_shadows,
        "plain diffuse, lit": diffuse,
        "plain diffuse, unlit": diffuse_unlit,
    }


def measure(ident: str, rounds: int, renders: int) -> dict[str, float]:
    env = visualenv.make(ident)
    env.reset(seed=0)
    for _ in range(5):
        env.step(env.action_space.sample() * 0)
    renderer = env.unwrapped.renderer
    switches = variants(renderer.scene)
    medians: dict[str, list[float]] = {name: [] for name in switches}
    for _ in range(rounds):
        for name, switch in switches.items():
            switch(True)
            for _ in range(3):  # the first renders after a change sync it
                renderer.raw_render()
            times = []
            for _ in range(renders):
                start = time.perf_counter()
                renderer.raw_render()
                times.append(time.perf_counter() - start)
            switch(False)
            medians[name].append(float(np.median(times)))
    env.close()
    return {name: 1000 * float(np.median(values)) for name, values in medians.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("ids", nargs="*", default=DEFAULT_IDS)
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--renders", type=int, default=60)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f}")
    rows = {ident: measure(ident, args.rounds, args.renders) for ident in args.ids}
    names = list(next(iter(rows.values())))
    print("| id | " + " | ".join(names) + " |")
    print("| --- |" + " ---: |" * len(names))
    for ident, row in rows.items():
        print(f"| {ident} | " + " | ".join(f"{row[name]:.2f}" for name in names) + " |")


if __name__ == "__main__":
    main()
