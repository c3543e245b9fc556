"""MKL inside torch (visualenv/compat/mkl.py): the documented MKL_CBWR pins it when set before its first call, the
service call used elsewhere is there on the torch checked, and torch moving makes this fail."""

from __future__ import annotations

import os
import platform
import subprocess
import sys

import pytest

torch = pytest.importorskip("torch")
from visualenv.compat import mkl  # noqa: E402

pytestmark = pytest.mark.skipif(
    not torch.backends.mkl.is_available() or platform.machine() != "x86_64",
    reason="this torch has no MKL (only x86-64 builds carry it)",
)


def in_a_fresh_process(code: str, **env: str) -> str:
    environment = {k: v for k, v in os.environ.items() if k != mkl.VARIABLE}
    run = subprocess.run(
        [sys.executable, "-c", code], env={**environment, **env}, capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr[-3000:]
    return run.stdout.strip()


def test_torch_is_a_version_the_service_call_was_checked_against():
    """Fails when torch moves: check that its libtorch_cpu still exports MKL's service functions, then add its version."""
    assert mkl.torch_checked(), f"torch {torch.__version__} is not in compat/mkl.py's CHECKED_TORCH {mkl.CHECKED_TORCH}"
    assert mkl.service() is not None, (
        f"libtorch_cpu of torch {torch.__version__} does not export {mkl.GET_SYMBOL}/{mkl.SET_SYMBOL}"
    )


PRODUCT = """
import os
from visualenv.compat import mkl
{before}
import torch
{after_import}
torch.randn(64, 64) @ torch.randn(64, 64)
{after_product}
print(mkl.branch(), os.environ.get("MKL_CBWR"))
"""


@pytest.mark.slow
def test_the_variable_pins_mkl_when_set_before_its_first_product():
    """MKL reads MKL_CBWR at its first call: in the environment from the start, or set after torch loads but before
    a product, it pins; set after a product, it is too late (what compatible_mode avoids by being entered first)."""
    compatible = str(mkl.COMPATIBLE_BRANCH)
    blank = {"before": "", "after_import": "", "after_product": ""}
    assert in_a_fresh_process(PRODUCT.format(**blank), MKL_CBWR="COMPATIBLE") == f"{compatible} COMPATIBLE"
    assert in_a_fresh_process(
        PRODUCT.format(**dict(blank, after_import="os.environ['MKL_CBWR'] = 'COMPATIBLE'"))
    ).startswith(compatible)
    assert not in_a_fresh_process(
        PRODUCT.format(**dict(blank, after_product="os.environ['MKL_CBWR'] = 'COMPATIBLE'"))
    ).startswith(compatible)
    assert not in_a_fresh_process(PRODUCT.format(**blank)).startswith(compatible)


def test_compatible_mode_pins_the_block_and_puts_the_variable_back():
    out = in_a_fresh_process("""
import os
from visualenv.compat import mkl
with mkl.compatible_mode():
    import torch
    torch.randn(64, 64) @ torch.randn(64, 64)
    print(mkl.pin(), mkl.branch(), end=" ")
print(os.environ.get("MKL_CBWR"))
""")
    assert out == f"True {mkl.COMPATIBLE_BRANCH} None"


@pytest.mark.slow
def test_a_process_visualenv_did_not_start_is_pinned_by_the_service_call_until_mkl_has_run():
    out = in_a_fresh_process("""
import os, torch
from visualenv.compat import mkl
print(mkl.pin(), mkl.branch(), os.environ.get("MKL_CBWR"), end=" ")
""")
    assert out == f"True {mkl.COMPATIBLE_BRANCH} None"  # the environment left alone
    late = in_a_fresh_process("""
import torch
from visualenv.compat import mkl
torch.randn(64, 64) @ torch.randn(64, 64)
print(mkl.pin())
""")
    assert late == "False"  # MKL took its mode at its first product: the record says unpinned


@pytest.mark.parametrize(
    "command, target",
    [
        (["eval", "LunarLanding-v0", "--model", "random", "--episodes", "1"], "evaluate_random"),
        (["play", "LunarLanding-v0", "--episodes", "1"], "play"),
    ],
)
def test_eval_and_play_run_with_the_variable_set_and_leave_it_as_it_was(command, target, monkeypatch):
    """The documented route for the processes visualenv starts: the command's work runs with MKL_CBWR=COMPATIBLE (what
    it loads and starts sees it), and the variable is put back once the command is done."""
    from click.testing import CliRunner

    from visualenv.cli import main
    from visualenv.errors import VisualEnvError
    from visualenv.train import evaluation, play

    seen = []

    def record(*args, **kwargs):
        seen.append(os.environ.get(mkl.VARIABLE))
        raise VisualEnvError("stopped here")

    monkeypatch.setattr(evaluation if target == "evaluate_random" else play, target, record)
    monkeypatch.delenv(mkl.VARIABLE, raising=False)
    result = CliRunner().invoke(main, command)
    assert "stopped here" in result.output and seen == [mkl.COMPATIBLE], (result.output, seen)
    assert mkl.VARIABLE not in os.environ
