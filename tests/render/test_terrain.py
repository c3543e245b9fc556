"""The ``terrain`` primitive: crater relief (numpy) and the shadows it casts under a low sun (real Blender)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from visualenv.compiler.render_plan import to_plan
from visualenv.render.plan import Craters
from visualenv.render.terrain import crater_field, crater_heights
from visualenv.spec import models


def craters_plan(**fields: object) -> Craters:
    """The render plan's craters of the spec's section with these fields."""
    return to_plan(models.Craters(**fields))


def test_a_crater_has_a_bowl_a_rim_and_ejecta():
    craters = craters_plan(count=1, radius=[2.0, 2.0], depth=0.2, rim=0.05, seed=3)
    ((cx, cy, radius),) = crater_field(craters, (40.0, 40.0))
    assert radius == pytest.approx(2.0)
    r = np.array([0.0, 0.5, 1.0, 2.0, 8.0]) * radius
    z = crater_heights(cx + r, np.full_like(r, cy), craters, (40.0, 40.0))
    diameter = 2 * radius
    assert z[0] == pytest.approx(0.05 * diameter - 0.2 * diameter)  # the floor: rim height less the depth
    assert z[2] == pytest.approx(0.05 * diameter)  # the rim
    assert z[3] == pytest.approx(0.05 * diameter / 8)  # ejecta fall off as r**-3
    assert z[0] < z[1] < z[2] and z[2] > z[3] > z[4] > 0


def test_craters_are_drawn_from_their_seed_inside_the_ground():
    craters = craters_plan(count=200, radius=[0.5, 6.0], seed=1)
    field = crater_field(craters, (100.0, 60.0))
    assert np.array_equal(field, crater_field(craters, (100.0, 60.0)))
    assert not np.array_equal(field, crater_field(replace(craters, seed=2), (100.0, 60.0)))
    assert (np.abs(field[:, 0]) <= 50).all() and (np.abs(field[:, 1]) <= 30).all()
    assert field[:, 2].min() >= 0.5 and field[:, 2].max() <= 6.0
    assert np.median(field[:, 2]) < (0.5 + 6.0) / 2  # log-uniform: small craters are the common ones


SCENE = """\
id: Terrain-v0
scene:
  world: {{color: [0, 0, 0], strength: 0}}
  objects:
    Ground: {{primitive: terrain, size: 40, segments: 200, smooth: true{craters}, material: {{color: [0.5, 0.5, 0.5], roughness: 1.0}}}}
    Sun: {{light: sun, strength: 5.0, rotation: [0, {sun_y}, 0]}}
    Cam: {{camera: orthographic, ortho_scale: {view}, location: [{cx}, {cy}, 20]}}
state: {{x: {{init: 0.0}}}}
actions: {{discrete: [{{u: 0}}]}}
observation: {{camera: Cam, resolution: [64, 64], color: grayscale}}
render: {{engine: cycles, preset: fast}}
"""


@pytest.mark.blender
@pytest.mark.parametrize("sun_y", [-1.22, 1.22], ids=["sun_from_west", "sun_from_east"])
def test_a_low_sun_leaves_the_near_wall_of_a_crater_in_shadow(tmp_path: Path, sun_y: float):
    pytest.importorskip("bpy")
    from visualenv.env import VisualEnv
    from visualenv.spec import load_spec_text

    # a seed whose one crater lies well inside the 40 m ground, so the view holds nothing but ground
    seed = next(
        s for s in range(100) if np.abs(crater_field(craters_plan(count=1, seed=s), (40.0, 40.0))[0, :2]).max() < 12
    )
    craters = craters_plan(count=1, radius=[3.0, 3.0], depth=0.2, rim=0.04, seed=seed)
    ((cx, cy, radius),) = crater_field(craters, (40.0, 40.0))
    view = 2.4 * radius

    def render(crater_text: str) -> np.ndarray:
        text = SCENE.format(craters=crater_text, sun_y=sun_y, view=view, cx=cx, cy=cy)
        env = VisualEnv(load_spec_text(text, name="t.yaml", base_dir=tmp_path))
        try:
            return env.reset(seed=0)[0][..., 0].astype(float)
        finally:
            env.close()

    def inner_wall(img: np.ndarray, side: int) -> float:
        """Mean brightness of the crater's inner wall on the west (-1) or east (+1) side."""
        px = lambda x: int(round((x / view + 0.5) * 64))  # noqa: E731 - metres from the centre to a pixel column
        cols = slice(px(0.4 * radius), px(0.85 * radius)) if side > 0 else slice(px(-0.85 * radius), px(-0.4 * radius))
        rows = slice(px(-0.3 * radius), px(0.3 * radius))
        return float(img[rows, cols].mean())

    cratered = render(f", craters: {{count: 1, radius: [3, 3], depth: 0.2, rim: 0.04, seed: {seed}}}")
    flat = render("")
    near, far = (-1, 1) if sun_y < 0 else (1, -1)  # rotation -1.22 about y: the light travels towards +x
    assert inner_wall(cratered, near) < 0.3 * inner_wall(cratered, far), (
        "the wall nearest the sun must lie in the rim's shadow"
    )
    assert abs(inner_wall(flat, -1) - inner_wall(flat, 1)) < 0.1 * inner_wall(flat, 1), "flat ground is lit evenly"
    assert inner_wall(flat, near) > 3 * inner_wall(cratered, near)
