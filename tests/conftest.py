"""Fixtures shared by several test modules, and the check that keeps the `blender` mark true.

The tests mirror the package (``tests/render/`` tests ``visualenv/render/``, ...). A test that renders with
Blender, reads a .blend or starts a process that does is marked ``blender`` where it lives: its module sets
``pytestmark = pytest.mark.blender``, or the test carries ``@pytest.mark.blender``. ``pytest -m "not blender"``
then runs the bpy-free core without Blender. The mark cannot rot: the unmarked tests run first, so one that
imports bpy (in its fixtures or its body) is the first in its process to do so, and fails and says so.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

CORPUS_SCRIPT = Path(__file__).parent / "fixtures" / "blend_corpus.py"
HAD_BPY = pytest.StashKey[bool]()


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The unmarked tests first (each group in its collected order): no `blender` test has imported bpy before an
    unmarked test runs, so the check below sees every unmarked test that imports it, not only the first."""
    items.sort(key=lambda item: item.get_closest_marker("blender") is not None)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_setup(item: pytest.Item) -> Iterator[None]:
    item.stash[HAD_BPY] = "bpy" in sys.modules
    return (yield)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item: pytest.Item) -> Iterator[None]:
    """Fail an unmarked test that is the first to import bpy: it renders, so it belongs to the `blender` tier."""
    outcome = yield
    if not item.stash.get(HAD_BPY, True) and "bpy" in sys.modules and item.get_closest_marker("blender") is None:
        pytest.fail(f"{item.nodeid} imported bpy but is not marked blender: mark its module or the test", pytrace=False)
    return outcome


@pytest.fixture(scope="session")
def corpus(tmp_path_factory) -> Path:
    """The .blend corpus (tests/fixtures/blend_corpus.py), written once per test session."""
    pytest.importorskip("bpy")
    folder = tmp_path_factory.mktemp("blend_corpus")
    subprocess.run([sys.executable, str(CORPUS_SCRIPT), str(folder)], check=True, capture_output=True, timeout=300)
    return folder
