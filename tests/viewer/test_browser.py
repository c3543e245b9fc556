"""The viewer in a real browser: a headless Chromium (npm @sparticuz/chromium, tests/fixtures/chromium.py) driven by
Playwright, on `visualenv view` started as a user starts it.

The arrow keys move the cart (the observation's pixels on the page change), a saved edit of the cart's colour shows
on the page, a broken edit shows its located error while the server goes on, the fix clears it, and
``--model pretrained`` plays Goalie without a key. The last test's page is README's screenshot: with
``VISUALENV_SCREENSHOT=1`` it writes docs/images/viewer.png (a small palette PNG).
"""

from __future__ import annotations

import io
import os
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests.fixtures.chromium import NodeMissing, setup
from tests.fixtures.viewer import ViewerProcess

pytestmark = pytest.mark.blender

REPO = Path(__file__).resolve().parents[2]
CARTPOLE = (REPO / "specs" / "visual_cartpole.yaml").read_text()
RED_CART = "material: {color: [0.8, 0.2, 0.2]}"
GREEN_CART = "material: {color: [0.1, 0.8, 0.1]}"
OBSERVATION, VIEW = 'img[data-kind="observation"]', 'img[data-kind="view"]'
SCREENSHOT = REPO / "docs" / "images" / "viewer.png"
SCREENSHOT_BYTES = 100_000  # the committed screenshot stays small


@pytest.fixture(scope="module")
def browser():
    try:
        chromium = setup()
    except NodeMissing as exc:
        pytest.skip(str(exc))
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        launched = playwright.chromium.launch(
            executable_path=str(chromium.executable), args=["--no-sandbox"], env={**os.environ, **chromium.env}
        )
        yield launched
        launched.close()


@pytest.fixture(scope="module")
def cartpole(tmp_path_factory):
    """A copy of the bundled CartPole (the tests edit it) in `visualenv view`."""
    spec = tmp_path_factory.mktemp("browser") / "cartpole.yaml"
    spec.write_text(CARTPOLE)
    with ViewerProcess([str(spec), "--view-size", "240"]) as process:
        process.spec = spec
        yield process


@pytest.fixture
def page(browser, cartpole):
    """The viewer's page at the start of the episode of seed 0."""
    page = browser.new_page(viewport={"width": 1120, "height": 660})
    page.goto(cartpole.url)
    page.wait_for_selector(OBSERVATION)
    episode = cartpole.state()["values"]["episode"]
    page.fill("#seed", "0")
    page.click("#reset")
    cartpole.wait_for(
        lambda s: s["values"]["episode"] > episode and s["values"]["seed"] == 0 and s["values"]["step"] == 0,
        60,
        "a reset",
    )
    wait_for_text(page, "#v-step", "0")
    yield page
    page.close()


def wait_for_text(page, selector: str, text: str, timeout: float = 60) -> None:
    page.wait_for_function(
        "([s, t]) => document.querySelector(s) && document.querySelector(s).textContent === t",
        arg=[selector, text],
        timeout=timeout * 1000,
    )


def pixels(page, selector: str) -> np.ndarray:
    """What the page shows of an element, as the browser drew it (RGB)."""
    page.wait_for_function("() => [...document.images].every((image) => image.complete)")
    return np.asarray(Image.open(io.BytesIO(page.locator(selector).screenshot())).convert("RGB")).astype(int)


def colored(image: np.ndarray, channel: int) -> int:
    """Pixels where `channel` (0 red, 1 green) stands out of the other two."""
    others = [c for c in range(3) if c != channel]
    return int(
        (
            (image[:, :, channel] > image[:, :, others[0]] + 60) & (image[:, :, channel] > image[:, :, others[1]] + 60)
        ).sum()
    )


def until(condition, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"no {what} within {timeout} s"
        time.sleep(0.3)


def test_the_arrow_keys_move_the_cart(page):
    before = pixels(page, OBSERVATION)
    assert before.shape[0] >= 300  # 100 x 100 shown at 3x, without smoothing
    for _ in range(6):
        page.keyboard.press("ArrowRight")  # a tap: one step
    wait_for_text(page, "#v-step", "6")
    until(
        lambda: (np.abs(pixels(page, OBSERVATION) - before).max(axis=2) > 16).sum() >= 90,
        60,
        "change of the observation on the page",
    )
    assert page.locator("#v-action").text_content() == "1: force = force_mag"


def test_an_edit_of_the_carts_colour_shows_on_the_page(page, cartpole):
    page.wait_for_selector(VIEW)
    until(lambda: colored(pixels(page, VIEW), 0) > 30, 60, "red cart in the view")
    assert colored(pixels(page, VIEW), 1) < 5
    cartpole.spec.write_text(CARTPOLE.replace(RED_CART, GREEN_CART, 1))
    try:
        until(
            lambda: colored(view := pixels(page, VIEW), 1) > 30 and colored(view, 0) < 5, 120, "green cart in the view"
        )
    finally:
        cartpole.spec.write_text(CARTPOLE)
        cartpole.wait_for(lambda s: s["values"]["builds"] >= 3, 120, "the original spec's build")


def test_a_broken_edit_shows_its_located_error_and_the_fix_clears_it(page, cartpole):
    spec: Path = cartpole.spec
    broken = CARTPOLE.replace("reward: 1.0", "reward: 1.0 + speedd")
    line = broken.splitlines().index("reward: 1.0 + speedd") + 1
    spec.write_text(broken)
    page.wait_for_selector("#error:not([hidden])", timeout=60_000)
    assert page.locator("#error").text_content().startswith(f"{spec}:{line}:15: reward: unknown name 'speedd'")
    page.keyboard.press("ArrowLeft")  # the last good env goes on, and the server with it
    wait_for_text(page, "#v-step", "1")
    assert "disconnected" not in page.locator("#status").text_content()
    spec.write_text(CARTPOLE)
    page.wait_for_selector("#error", state="hidden", timeout=120_000)


@pytest.mark.slow  # a minute: the shipped agent plays whole episodes in the page
def test_the_pretrained_agent_plays_goalie_without_a_key(browser, tmp_path):
    with ViewerProcess(["Goalie-v0", "--model", "pretrained"]) as goalie:
        page = browser.new_page(viewport={"width": 1120, "height": 660})
        try:
            page.goto(goalie.url)
            page.wait_for_selector(OBSERVATION)
            first = pixels(page, OBSERVATION)
            page.wait_for_function("() => Number(document.getElementById('v-step').textContent) >= 5", timeout=120_000)
            # the step's number shows before its image has loaded on a busy machine: polled, not read once
            until(
                lambda: (np.abs(pixels(page, OBSERVATION) - first).max(axis=2) > 16).sum() > 100,
                60,
                "a changed observation",
            )
            assert (
                page.locator("#mode").text_content().startswith("agent: ")
                and "Goalie-v0" in page.locator("#mode").text_content()
            )
            page.wait_for_selector(VIEW, timeout=120_000)
            shot = tmp_path / "viewer.png"
            page.screenshot(path=str(shot))
            assert np.asarray(Image.open(shot)).std() > 10
            if os.environ.get("VISUALENV_SCREENSHOT"):
                save_small(shot, SCREENSHOT)
        finally:
            page.close()


def save_small(source: Path, target: Path) -> None:
    """README's screenshot: a palette of 64 colours keeps it under SCREENSHOT_BYTES."""
    image = Image.open(source).convert("RGB").quantize(colors=64, method=Image.Quantize.MEDIANCUT)
    target.parent.mkdir(parents=True, exist_ok=True)
    image.save(target, optimize=True)
    assert target.stat().st_size < SCREENSHOT_BYTES, target.stat().st_size
