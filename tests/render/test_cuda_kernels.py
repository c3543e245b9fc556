"""`visualenv compile-kernels`: Cycles' CUDA PTX compiled ahead into visualenv's kernel cache, outside bpy (no GPU needed)."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

zstandard = pytest.importorskip("zstandard", reason="a dependency of bpy")
kernels = pytest.importorskip("visualenv.render.blender.runtime.cuda_kernels", reason="the Blender backend needs bpy")

from visualenv.cli import main  # noqa: E402
from visualenv.compat import blender as compat  # noqa: E402
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
    folder.mkdir(parents=True, exist_ok=True)
    for n in computes:
        (folder / f"kernel_compute_{n}.ptx.zst").write_bytes(
            zstandard.ZstdCompressor().compress(PTX.replace("sm_75", f"sm_{n}").encode())
        )
    return folder


def test_the_highest_ptx_not_above_the_architecture_is_compiled(tmp_path):
    lib = fake_lib(tmp_path / "lib", 50, 75, 120)
    assert kernels.source_ptx("sm_90", lib).name == "kernel_compute_75.ptx.zst"
    assert kernels.source_ptx("sm_52", lib).name == "kernel_compute_50.ptx.zst"
    with pytest.raises(ConfigError, match="no PTX that compiles for sm_30 .*compute_50, compute_75, compute_120"):
        kernels.source_ptx("sm_30", lib)


@pytest.fixture
def cache(tmp_path, monkeypatch) -> Path:
    """An empty XDG cache folder: visualenv's kernel cache goes under it."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    return tmp_path / "xdg" / "visualenv" / "cycles"


def stand_in_ptxas(folder: Path) -> Path:
    """A ptxas that writes an ELF header where it is told to (a real one needs the CUDA toolkit)."""
    tool = folder / "ptxas"
    tool.write_text('#!/bin/sh\nwhile [ "$1" != "-o" ]; do shift; done\nprintf "\\177ELF stand-in" > "$2"\n')
    tool.chmod(0o755)
    return tool


def listing(folder: Path) -> list[tuple[str, int, int]]:
    return sorted((str(p.relative_to(folder)), p.stat().st_size, p.stat().st_mtime_ns) for p in folder.rglob("*"))


def test_the_cache_is_keyed_by_bpys_version_and_the_ptxs_hash(tmp_path, cache):
    lib = fake_lib(tmp_path / "lib", 75)
    ptx = lib / "kernel_compute_75.ptx.zst"
    path = compat.cached_kernel("sm_90", ptx, "5.0.1")
    assert path.parent.parent == cache / "bpy-5.0.1" and path.name == "kernel_sm_90.cubin.zst"
    assert path.parent.name.startswith("kernel_compute_75-")
    assert compat.cached_kernel("sm_90", ptx, "5.0.2") != path
    ptx.write_bytes(zstandard.ZstdCompressor().compress(b"// another kernel"))
    assert compat.cached_kernel("sm_90", ptx, "5.0.1") != path


def test_the_cache_is_the_users_cache_folder(monkeypatch):
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    assert compat.kernel_cache() == Path.home() / ".cache" / "visualenv" / "cycles"
    monkeypatch.setenv("XDG_CACHE_HOME", "/elsewhere")
    assert compat.kernel_cache() == Path("/elsewhere/visualenv/cycles")


def test_a_compiled_kernel_goes_to_the_cache_and_nothing_into_the_kernel_folder(tmp_path, cache):
    lib = fake_lib(tmp_path / "lib", 75)
    before = listing(lib)
    path = kernels.compile_cuda_kernels("sm_90", lib=lib, ptxas=str(stand_in_ptxas(tmp_path)))
    assert path == compat.cached_kernel("sm_90", lib / "kernel_compute_75.ptx.zst", compat.bpy_version())
    assert path.is_relative_to(cache)
    assert zstandard.ZstdDecompressor().decompressobj().decompress(path.read_bytes()) == b"\x7fELF stand-in"
    assert listing(lib) == before
    assert [p.name for p in path.parent.iterdir()] == ["kernel_sm_90.cubin.zst"]  # nothing partial left


def test_the_cuda_toolkits_ptxas_compiles_a_binary_into_the_cache(tmp_path, cache):
    try:
        ptxas = kernels.find_ptxas()
    except ConfigError:
        pytest.skip("no CUDA toolkit (ptxas) on this machine")
    lib = fake_lib(tmp_path / "lib", 75)
    path = kernels.compile_cuda_kernels(
        "sm_80", lib=lib, ptxas=ptxas
    )  # an architecture every toolkit from CUDA 11 to 13 builds
    assert path.is_relative_to(cache) and path.name == "kernel_sm_80.cubin.zst"
    assert zstandard.ZstdDecompressor().decompressobj().decompress(path.read_bytes())[:4] == b"\x7fELF"


def test_cycles_uses_only_binaries_of_the_ptx_it_ships_now_for_archs_it_has_no_binary_for(tmp_path, cache, monkeypatch):
    addon = tmp_path / "cycles"
    lib = fake_lib(addon / "lib", 75)
    (lib / "kernel_sm_86.cubin.zst").write_bytes(b"shipped")
    (addon / "shader").mkdir()
    monkeypatch.setattr(compat, "bpy_version", lambda: "5.0.1")
    ptx = lib / "kernel_compute_75.ptx.zst"
    for arch in ("sm_90", "sm_86"):
        compat.cached_kernel(arch, ptx, "5.0.1").parent.mkdir(parents=True, exist_ok=True)
        compat.cached_kernel(arch, ptx, "5.0.1").write_bytes(b"compiled")
    stale = (
        cache / "bpy-5.0.1" / "kernel_compute_75-0000000000000000" / "kernel_sm_89.cubin.zst"
    )  # from a PTX bpy no longer has
    stale.parent.mkdir()
    stale.write_bytes(b"compiled")
    older = cache / "bpy-4.5.0" / compat.cached_kernel("sm_80", ptx, "5.0.1").parent.name / "kernel_sm_80.cubin.zst"
    older.parent.mkdir(parents=True)
    older.write_bytes(b"compiled")
    found = compat.cached_kernels(addon)
    assert found == {"sm_90": compat.cached_kernel("sm_90", ptx, "5.0.1")}
    before = listing(addon)
    folder = compat.cycles_folder_with(found, addon)
    assert folder.is_relative_to(cache) and compat.cycles_folder_with(found, addon) == folder
    assert {p.name: p.resolve() for p in folder.iterdir()} == {
        "lib": folder / "lib",
        "shader": (addon / "shader").resolve(),
    }
    assert {p.name: p.resolve() for p in (folder / "lib").iterdir()} == {
        **{p.name: p.resolve() for p in lib.iterdir()},
        "kernel_sm_90.cubin.zst": found["sm_90"],
    }
    assert listing(addon) == before


def test_a_missing_or_failing_ptxas_and_a_bad_architecture_are_told(tmp_path):
    lib = fake_lib(tmp_path / "lib", 75)
    with pytest.raises(ConfigError, match="needs the CUDA toolkit's ptxas .*nope is not an executable file"):
        kernels.compile_cuda_kernels("sm_90", lib=lib, ptxas=str(tmp_path / "nope"))
    failing = tmp_path / "ptxas"
    failing.write_text("#!/bin/sh\necho 'ptxas fatal: no good' >&2\nexit 1\n")
    failing.chmod(0o755)
    with pytest.raises(
        ConfigError, match="could not compile kernel_compute_75.ptx.zst for sm_90: ptxas fatal: no good"
    ):
        kernels.compile_cuda_kernels("sm_90", lib=lib, ptxas=str(failing))
    assert not list(lib.glob("*cubin*"))
    with pytest.raises(ConfigError, match="expected a CUDA architecture such as sm_90, got '90'"):
        kernels.compile_cuda_kernels("90", lib=lib, ptxas=str(failing))


def test_the_command_explains_instead_of_failing(tmp_path, cache):
    result = CliRunner().invoke(main, ["compile-kernels", "--arch", "sm_90", "--ptxas", str(tmp_path / "nope")])
    assert result.exit_code == 1 and "error: compiling Cycles' kernels needs the CUDA toolkit's ptxas" in result.output
    assert "Traceback" not in result.output
    stand_in = tmp_path / "ptxas"  # never run: bpy ships sm_75's binary
    stand_in.write_text("#!/bin/sh\nexit 1\n")
    stand_in.chmod(0o755)
    result = CliRunner().invoke(main, ["compile-kernels", "--arch", "sm_75", "--ptxas", str(stand_in)])
    assert result.exit_code == 0 and "sm_75: bpy already has its binary" in result.output, result.output


def test_the_command_writes_to_the_cache_and_leaves_bpy_as_installed(tmp_path, cache):
    bpy_lib = compat.cycles_addon() / "lib"
    before = listing(bpy_lib)
    tool = str(stand_in_ptxas(tmp_path))
    result = CliRunner().invoke(main, ["compile-kernels", "--arch", "sm_90", "--ptxas", tool])
    assert result.exit_code == 0, result.output
    assert listing(bpy_lib) == before
    assert compat.cached_kernels() == {
        "sm_90": compat.cached_kernel("sm_90", bpy_lib / "kernel_compute_75.ptx.zst", compat.bpy_version())
    }
    assert str(compat.cached_kernels()["sm_90"]) in result.output
    again = CliRunner().invoke(main, ["compile-kernels", "--arch", "sm_90", "--ptxas", tool])
    assert again.exit_code == 0 and "sm_90: already compiled" in again.output, again.output
