"""Fixtures shared by several test modules."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

CORPUS_SCRIPT = Path(__file__).parent / "fixtures" / "blend_corpus.py"


@pytest.fixture(scope="session")
def corpus(tmp_path_factory) -> Path:
    """The .blend corpus (tests/fixtures/blend_corpus.py), written once per test session."""
    pytest.importorskip("bpy")
    folder = tmp_path_factory.mktemp("blend_corpus")
    subprocess.run([sys.executable, str(CORPUS_SCRIPT), str(folder)], check=True, capture_output=True, timeout=300)
    return folder
