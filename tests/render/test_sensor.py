"""The camera sensor model (observation.sensor): noise, gain, gamma and vignetting on real renders, seeded like the env."""

from __future__ import annotations

import numpy as np
import pytest

from visualenv.env.batch import BatchedVectorEnv
from visualenv.env.visual_env import VisualEnv
from visualenv.errors import SpecError
from visualenv.spec import load_spec_text

pytestmark = pytest.mark.blender

#: a flat grey sky and nothing else: every clean pixel is the same, in one env or a batch's tile
FLAT = """\
id: Flat-v0
scene:
  world: {{color: [0.2, 0.2, 0.2], strength: 1.0}}
  objects:
    Cam: {{camera: perspective, location: [0, 0, 5]}}
state:
  x: {{init: "uniform(-1, 1)"}}
actions:
  discrete: [{{}}, {{}}]
observation:
  camera: Cam
  resolution: [32, 32]
  color: {color}
{sensor}
max_steps: 5
"""


def flat(sensor: str = "", color: str = "grayscale") -> str:
    return FLAT.format(color=color, sensor=f"  sensor: {sensor}" if sensor else "")


def frames(text: str, seed: int, steps: int = 2, name: str = "flat.yaml") -> list[np.ndarray]:
    env = VisualEnv(load_spec_text(text, name=name))
    try:
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for _ in range(steps):
            out.append(env.step(0)[0])
        return out
    finally:
        env.close()


def test_read_noise_has_its_std_and_the_same_seed_gives_the_same_frames():
    clean = frames(flat(), seed=0, steps=0)[0].astype(float)
    assert clean.std() == 0  # the flat sky: any spread below is the sensor's
    noisy = frames(flat("{read_noise: 0.05}"), seed=7)
    again = frames(flat("{read_noise: 0.05}"), seed=7)
    other = frames(flat("{read_noise: 0.05}"), seed=8)
    assert all(np.array_equal(a, b) for a, b in zip(noisy, again))
    assert not np.array_equal(noisy[0], other[0])
    assert not np.array_equal(noisy[0], noisy[1])  # fresh noise every frame
    spread = noisy[0].astype(float) - clean
    assert abs(spread.std() - 0.05 * 255) < 1.5, spread.std()
    assert abs(spread.mean()) < 1.0


def test_shot_noise_grows_with_intensity_and_gain_and_gamma_change_exposure():
    clean = float(frames(flat(), seed=0, steps=0)[0].mean())  # about 124 (0.2 linear in sRGB)
    bright = frames(flat("{shot_noise: 0.05}"), seed=1, steps=0)[0].astype(float)
    expected = 0.05 * np.sqrt(clean / 255) * 255
    assert abs(bright.std() - expected) < 1.5, (bright.std(), expected)
    gained = frames(flat("{gain: 1.5}"), seed=1, steps=0)[0]
    assert np.all(gained == min(255, round(clean * 1.5)))
    curved = frames(flat("{gamma: 2.0}"), seed=1, steps=0)[0]
    assert np.all(np.abs(curved.astype(float) - (clean / 255) ** 2 * 255) <= 1)


def test_vignetting_darkens_the_corners_not_the_centre():
    clean = float(frames(flat(), seed=0, steps=0)[0].mean())
    image = frames(flat("{vignetting: 0.5}"), seed=0, steps=0)[0][:, :, 0].astype(float)
    centre, corner = image[15:17, 15:17].mean(), image[0, 0]
    assert abs(centre - clean) <= 1.5
    assert abs(corner - clean * (1 - 0.5 * (31 / 32) ** 2)) <= 1.5, corner
    assert image[0, 0] < image[0, 16] < image[16, 16]


def test_a_batch_env_draws_the_noise_of_the_single_env_seeded_s_plus_i():
    text = flat("{read_noise: 0.04, shot_noise: 0.02}", color="rgb")
    batch = BatchedVectorEnv(load_spec_text(text, name="flat.yaml"), 3)
    try:
        obs, _ = batch.reset(seed=10)
        steps = [obs] + [batch.step(np.zeros(3, dtype=np.int64))[0] for _ in range(2)]
    finally:
        batch.close()
    for i in range(3):
        single = frames(text, seed=10 + i)
        for t in range(3):
            assert np.array_equal(steps[t][i], single[t]), (i, t)
    assert not np.array_equal(steps[0][0], steps[0][1])


def test_a_dict_observation_takes_a_sensor_per_camera_and_toml_works():
    text = """\
id = "FlatDict-v0"
max_steps = 5
[scene.world]
color = [0.2, 0.2, 0.2]
[scene.objects.Cam]
camera = "perspective"
location = [0, 0, 5]
[state.x]
init = 0.0
[actions]
discrete = [{}, {}]
[observation.cameras.noisy]
camera = "Cam"
resolution = [16, 16]
sensor = {read_noise = 0.05}
[observation.cameras.clean]
camera = "Cam"
resolution = [16, 16]
"""
    obs = frames(text, seed=3, steps=0, name="flat.toml")[0]
    assert obs["clean"].std() == 0 and obs["noisy"].std() > 5


@pytest.mark.parametrize(
    "observation, message",
    [
        ("  sensor: {read_noise: 0.1}\n  color: depth\n", "a sensor model acts on light"),
        ("  sensor: {read_noise: -0.1}\n", "greater than or equal to 0"),
        ("  sensor: {readnoise: 0.1}\n", "readnoise"),
    ],
)
def test_bad_sensors_are_located_spec_errors(observation, message):
    text = "id: Bad-v0\nstate: {x: {init: 0}}\nactions: {discrete: [{}]}\nobservation:\n  camera: Cam\n" + observation
    with pytest.raises(SpecError, match=message) as err:
        load_spec_text(text, name="bad.yaml")
    assert "bad.yaml:" in str(err.value)


def test_same_step_autoreset_draws_the_noise_one_env_draws_at_its_end_and_its_next_reset():
    text = flat("{read_noise: 0.05}").replace("max_steps: 5", "max_steps: 2")
    batch = BatchedVectorEnv(load_spec_text(text, name="flat.yaml"), 2, autoreset_mode="SAME_STEP")
    singles = [VisualEnv(load_spec_text(text, name="flat.yaml")) for _ in range(2)]
    try:
        batch.reset(seed=20)
        for i, env in enumerate(singles):
            env.reset(seed=20 + i)
        for _ in range(2):
            obs, _, _, truncated, info = batch.step(np.zeros(2, dtype=np.int64))
            own = [env.step(0) for env in singles]
        assert truncated.all()
        for i, env in enumerate(singles):
            assert np.array_equal(info["final_obs"][i], own[i][0])
            assert np.array_equal(obs[i], env.reset()[0])  # the next episode's first frame, drawn after the last one
    finally:
        batch.close()
        for env in singles:
            env.close()
