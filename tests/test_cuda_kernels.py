"""`visualenv compile-kernels`: Cycles' CUDA PTX compiled ahead into bpy's kernel folder (no GPU needed)."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

zstandard = pytest.importorskip("zstandard", reason="a dependency of bpy")
kernels = pytest.importorskip("visualenv.render.blender.cuda_kernels", reason="the Blender backend needs bpy")

from visualenv.cli import main  # noqa: E402
from visualenv.errors import ConfigError  # noqa: E402

PTX = """.version 7.0
.target sm_75
.address_size 64

.visible .entry visualenv_noop()
{
\tret;
}
"""


def fake_lib(folder: Path, *computes: int) -> Path:
    """A kernel folder as bpy's, with a tiny kernel as each compute_XY PTX."""
    folder.mkdir(exist_ok=True)
    for n in computes:
        (folder / f"kernel_compute_{n}.ptx.zst").write_bytes(zstandard.ZstdCompressor().compress(PTX.replace("sm_75", f"sm_{n}").encode()))
    return folder


def test_the_highest_ptx_not_above_the_architecture_is_compiled(tmp_path):
    lib = fake_lib(tmp_path / "lib", 50, 75, 120)
    assert kernels.source_ptx("sm_90", lib).name == "kernel_compute_75.ptx.zst"
    assert kernels.source_ptx("sm_52", lib).name == "kernel_compute_50.ptx.zst"
    with pytest.raises(ConfigError, match="no PTX that compiles for sm_30 .*compute_50, compute_75, compute_120"):
        kernels.source_ptx("sm_30", lib)


def test_a_compiled_kernel_lands_beside_bpys_as_cycles_names_it(tmp_path):
    try:
        ptxas = kernels.find_ptxas()
    except ConfigError:
        pytest.skip("no CUDA toolkit (ptxas) on this machine")
    lib = fake_lib(tmp_path / "lib", 75)
    path = kernels.compile_cuda_kernels("sm_80", lib=lib, ptxas=ptxas)   # an architecture every toolkit from CUDA 11 to 13 builds
    assert path == lib / "kernel_sm_80.cubin.zst"
    assert zstandard.ZstdDecompressor().decompressobj().decompress(path.read_bytes())[:4] == b"\x7fELF"
    assert sorted(p.name for p in lib.iterdir()) == ["kernel_compute_75.ptx.zst", "kernel_sm_80.cubin.zst"]  # nothing partial left


def test_a_missing_or_failing_ptxas_and_a_bad_architecture_are_told(tmp_path):
    lib = fake_lib(tmp_path / "lib", 75)
    with pytest.raises(ConfigError, match="needs the CUDA toolkit's ptxas .*nope is not an executable file"):
        kernels.compile_cuda_kernels("sm_90", lib=lib, ptxas=str(tmp_path / "nope"))
    failing = tmp_path / "ptxas"
    failing.write_text("#!/bin/sh\necho 'ptxas fatal: no good' >&2\nexit 1\n")
    failing.chmod(0o755)
    with pytest.raises(ConfigError, match="could not compile kernel_compute_75.ptx.zst for sm_90: ptxas fatal: no good"):
        kernels.compile_cuda_kernels("sm_90", lib=lib, ptxas=str(failing))
    assert not list(lib.glob("*cubin*"))
    with pytest.raises(ConfigError, match="expected a CUDA architecture such as sm_90, got '90'"):
        kernels.compile_cuda_kernels("90", lib=lib, ptxas=str(failing))


def test_the_command_explains_instead_of_failing(tmp_path):
    result = CliRunner().invoke(main, ["compile-kernels", "--arch", "sm_90", "--ptxas", str(tmp_path / "nope")])
    assert result.exit_code == 1 and "error: compiling Cycles' kernels needs the CUDA toolkit's ptxas" in result.output
    assert "Traceback" not in result.output
    stand_in = tmp_path / "ptxas"   # never run: bpy ships sm_75's binary
    stand_in.write_text("#!/bin/sh\nexit 1\n")
    stand_in.chmod(0o755)
    result = CliRunner().invoke(main, ["compile-kernels", "--arch", "sm_75", "--ptxas", str(stand_in)])
    assert result.exit_code == 0 and "sm_75: bpy already has its binary" in result.output, result.output
