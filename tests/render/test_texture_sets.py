"""Texture sets: a material's image texture names several files and an actor's ``texture`` picks one per step or episode."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from visualenv.errors import SpecError
from visualenv.spec import load_spec_text

pytestmark = pytest.mark.blender

COLOURS = {"red.png": (220, 30, 30), "green.png": (30, 220, 30), "blue.png": (30, 30, 220)}

#: an emissive textured plane filling an orthographic camera's view: the pixels are the texture's colour
SPEC = """\
id: Tex-v0
scene:
  objects:
    Card: {{primitive: plane, size: 4, material: {{emission: [1, 1, 1], emission_strength: 0, texture: {{type: image, image: [red.png, green.png, blue.png]}}}}}}
    Sun: {{light: sun, strength: 3}}
    Cam: {{camera: orthographic, ortho_scale: 2, location: [0, 0, 5]}}
state:
  k: {{init: "{init}"}}
actions: {{discrete: [{{}}]}}
dynamics: {{update: {{k: k + 1}}}}
actors: {{Card: {{texture: k{color}}}}}
observation: {{camera: Cam, resolution: [8, 8], color: rgb}}
"""


def make_textures(folder: Path) -> None:
    for name, colour in COLOURS.items():
        Image.fromarray(np.full((8, 8, 3), colour, dtype=np.uint8)).save(folder / name)


def which(frame: np.ndarray) -> int:
    """0, 1 or 2: the channel that dominates the frame (red, green or blue texture)."""
    return int(np.argmax(frame.reshape(-1, 3).mean(axis=0)))


def test_texture_picks_a_file_each_step_modulo_the_set(tmp_path):
    from visualenv.env.visual_env import VisualEnv

    make_textures(tmp_path)
    env = VisualEnv(load_spec_text(SPEC.format(init=1.0, color=""), name="tex.yaml", base_dir=tmp_path))
    try:
        seen = [env.reset(seed=0)[0]] + [env.step(0)[0] for _ in range(3)]
    finally:
        env.close()
    assert [which(f) for f in seen] == [1, 2, 0, 1]  # k = 1, 2, 3, 4: green, blue, red (3 % 3), green
    assert all(f.reshape(-1, 3).std(axis=0).max() < 20 for f in seen)  # the whole view is the one texture


def test_a_texture_drawn_at_reset_and_a_bound_colour_share_the_material(tmp_path):
    from visualenv.env.visual_env import VisualEnv

    make_textures(tmp_path)
    text = SPEC.format(init="randint(0, 2)", color=", color: [1, 1, 1]").replace("k: k + 1", "k: k")
    env = VisualEnv(load_spec_text(text, name="tex.yaml", base_dir=tmp_path))
    try:
        picks = {}
        for seed in range(6):
            obs, info = env.reset(seed=seed)
            picks[seed] = (which(obs), int(info["state"]["k"]))
    finally:
        env.close()
    assert all(seen == k for seen, k in picks.values()), picks
    assert len({k for _, k in picks.values()}) >= 2


def test_a_batch_gives_each_env_its_own_texture(tmp_path):
    from visualenv.env.batch import BatchedVectorEnv

    make_textures(tmp_path)
    text = SPEC.format(init="randint(0, 2)", color="")
    batch = BatchedVectorEnv(load_spec_text(text, name="tex.yaml", base_dir=tmp_path), 4)
    try:
        obs, info = batch.reset(seed=0)
        ks = info["state"]["k"].astype(int)
        assert [which(obs[i]) for i in range(4)] == [k % 3 for k in ks]
        obs, _, _, _, info = batch.step(np.zeros(4, dtype=np.int64))
        assert [which(obs[i]) for i in range(4)] == [(k + 1) % 3 for k in ks]
    finally:
        batch.close()
    assert len(set(ks % 3)) >= 2, ks  # seeds 0..3 drew different textures: one render showed several


def test_a_texture_binding_needs_a_texture_set_and_toml_takes_one(tmp_path):
    from visualenv.env.visual_env import VisualEnv

    make_textures(tmp_path)
    single = SPEC.format(init=0.0, color="").replace("image: [red.png, green.png, blue.png]", "image: red.png")
    env = VisualEnv(load_spec_text(single, name="tex.yaml", base_dir=tmp_path))
    try:
        with pytest.raises(SpecError, match="no material of 'Card' has one") as err:
            env.reset(seed=0)
        assert "tex.yaml:11" in str(err.value)
    finally:
        env.close()
    missing = SPEC.format(init=0.0, color="").replace("green.png", "gone.png")
    env = VisualEnv(load_spec_text(missing, name="tex.yaml", base_dir=tmp_path))
    try:
        with pytest.raises(SpecError, match=r"image file not found: .*gone.png") as err:
            env.reset(seed=0)
        assert "scene.objects.Card.material.texture.image[1]" in str(err.value)
    finally:
        env.close()
    toml = (
        'id = "T-v0"\n[state.k]\ninit = 0\n[actions]\ndiscrete = [{}]\n[actors.Card]\ntexture = "k"\n'
        '[scene.objects.Card]\nprimitive = "plane"\nmaterial = {texture = {type = "image", image = ["a.png", "b.png"]}}\n'
    )
    assert load_spec_text(toml, name="t.toml").spec.scene.objects["Card"].material.texture.image == ["a.png", "b.png"]


def test_goalie_randomizeds_images_are_made_by_its_script(tmp_path):
    import subprocess
    import sys

    assets = Path(__file__).parents[2] / "specs" / "assets"
    subprocess.run(
        [sys.executable, str(assets / "make_goalie_assets.py"), str(tmp_path)],
        check=True,
        capture_output=True,
        timeout=120,
    )
    made = sorted(p.name for p in tmp_path.glob("*.png"))
    assert made == sorted(p.name for p in (assets / "goalie").glob("*.png")) and len(made) == 4
    for name in made:
        assert (tmp_path / name).read_bytes() == (assets / "goalie" / name).read_bytes(), name
