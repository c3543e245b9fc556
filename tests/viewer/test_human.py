"""render_mode="human" follows Gymnasium: the env resets, steps and closes as ever, render() returns None, and every
step is shown on the viewer's page (the observation as rendered; the view while a page watches; a batch's grid).
"""

from __future__ import annotations

import io
import json
import threading
import urllib.request
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from PIL import Image

import visualenv
from visualenv.env.batch import BatchedVectorEnv
from visualenv.viewer.human import shared_board

pytestmark = pytest.mark.blender

REPO = Path(__file__).resolve().parents[2]


def page_state(url: str) -> dict:
    with urllib.request.urlopen(url + "state", timeout=30) as response:
        return json.load(response)


def page_picture(url: str, name: str) -> np.ndarray:
    with urllib.request.urlopen(url + "picture/" + name, timeout=30) as response:
        return np.asarray(Image.open(io.BytesIO(response.read())))


def test_gymnasium_make_in_human_mode_resets_steps_renders_and_closes(capfd):
    env = gym.make("visualenv/VisualCartPole-v0", render_mode="human")
    obs, _ = env.reset(seed=0)
    for _ in range(3):
        obs, reward, terminated, truncated, info = env.step(1)
    assert env.render() is None
    _, url = shared_board()
    state = page_state(url)
    assert (
        state["values"]["env"] == "VisualCartPole-v0"
        and state["values"]["step"] == 3
        and state["values"]["return"] == 3.0
    )
    assert state["values"]["state"]["x"] == pytest.approx(info["state"]["x"])
    np.testing.assert_array_equal(page_picture(url, "observation"), obs[:, :, 0])  # the observation as the agent got it
    env.close()
    assert page_state(url)["values"]["status"] == "closed"
    again = gym.make("visualenv/VisualCartPole-v0", render_mode="human")
    again.reset(seed=1)
    again.close()
    printed = capfd.readouterr().err
    assert printed.count(f"render_mode='human' shows the env at {url}") <= 1  # the URL, once per process


def test_check_env_passes_in_human_mode():
    env = visualenv.make("VisualCartPole-v0", render_mode="human")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # check_env makes the env in each render mode: no warning
            check_env(env.unwrapped)
    finally:
        env.close()


def test_a_watching_page_gets_the_view_too(tmp_path):
    spec = tmp_path / "cartpole.yaml"
    spec.write_text(
        (REPO / "specs" / "visual_cartpole.yaml")
        .read_text()
        .replace(
            "render: {engine: cycles, preset: fast, device: cpu}",
            "render: {engine: cycles, preset: fast, device: cpu, view: {preset: fast, resolution: [80, 60]}}",
        )
    )
    board, url = shared_board()
    watching = threading.Event()

    def watch():
        with urllib.request.urlopen(url + "events", timeout=60) as stream:
            watching.set()
            for line in stream:
                if line.startswith(b"data: ") and "view" in json.loads(line[6:])["pictures"]:
                    return

    page = threading.Thread(target=watch, daemon=True)
    page.start()
    assert watching.wait(30)
    env = visualenv.make(str(spec), render_mode="human")
    try:
        env.reset(seed=0)
        for _ in range(20):  # views are paced: one within a few steps
            env.step(0)
            if "view" in page_state(url)["pictures"]:
                break
        assert page_state(url)["pictures"]["view"]["width"] == 80
        assert page_picture(url, "view").shape == (60, 80, 3)
    finally:
        env.close()
    page.join(timeout=30)


def test_a_batch_in_human_mode_shows_a_grid_of_its_observations():
    batch = visualenv.make_vec("VisualCartPole-v0", 4, batched=True, render_mode="human")
    try:
        obs, _ = batch.reset(seed=0)
        obs, *_ = batch.step(np.array([0, 1, 0, 1]))
        assert batch.render() is None
        _, url = shared_board()
        assert page_state(url)["values"]["envs"] == 4
        tiled = page_picture(url, "observation")
        assert tiled.shape == (201, 201)  # 2 x 2 tiles of 100 x 100, 1 px apart
        for i in range(4):
            r, c = divmod(i, 2)
            np.testing.assert_array_equal(tiled[r * 101 : r * 101 + 100, c * 101 : c * 101 + 100], obs[i, :, :, 0])
    finally:
        batch.close()
    with pytest.raises(ValueError, match="state-only batch"):
        BatchedVectorEnv("VisualCartPole-v0", 2, render=False, render_mode="human")
