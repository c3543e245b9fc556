"""Every bundled id renders the frames it rendered before the render path became one (issue 60).

``tests/fixtures/bundled_frames.npz`` holds each id's reset and two seeded steps, recorded by
``tests/fixtures/bundled_frames.py`` from the code before the change. On the machine that recorded them the frames
are the same bytes; on another CPU Cycles' kernels may round a pixel a level apart (``CYCLES_CPU_NO_AVX2=1``: at most
one level, in a handful of pixels), so a frame may differ by more than 2 levels in at most 0.1 % of its pixels: fewer
than one step of VisualCartPole's cart moves.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("bpy")

from tests.fixtures.bundled_frames import bundled_ids, frames  # noqa: E402
from tests.paths import TESTS  # noqa: E402

pytestmark = pytest.mark.blender

RECORD = TESTS / "fixtures" / "bundled_frames.npz"
#: a frame may differ by more than LEVELS in at most this share of its pixels
LEVELS, SHARE = 2, 0.001


def test_the_record_holds_every_bundled_id() -> None:
    with np.load(RECORD) as record:
        assert sorted(record.files) == bundled_ids()


@pytest.mark.parametrize("env_id", bundled_ids())
def test_the_id_renders_its_recorded_frames(env_id: str) -> None:
    with np.load(RECORD) as record:
        expected = record[env_id]
    seen = frames(env_id)
    assert seen.shape == expected.shape and seen.dtype == np.uint8
    off = np.abs(seen.astype(np.int16) - expected.astype(np.int16)) > LEVELS
    share = off.reshape(len(seen), -1).mean(axis=1)
    assert (share <= SHARE).all(), f"{env_id}: share of pixels off by more than {LEVELS} levels per frame: {share}"


def test_the_comparison_sees_a_moved_object() -> None:
    """Not vacuous: VisualCartPole's reset frame against its own second step fails the same bound."""
    with np.load(RECORD) as record:
        cartpole = record["VisualCartPole-v0"]
    off = np.abs(cartpole[0].astype(np.int16) - cartpole[2].astype(np.int16)) > LEVELS
    assert off.mean() > SHARE
