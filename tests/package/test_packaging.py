"""The wheel carries the bundled specs, so an installed (not editable) visualenv finds them by id; the docs list every
package; README and the repository stay within the house's limits."""

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_an_installed_wheel_finds_the_bundled_specs(tmp_path):
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "-q",
            "--no-deps",
            "--no-build-isolation",
            "-w",
            str(tmp_path / "dist"),
            str(ROOT),
        ],
        check=True,
        capture_output=True,
    )
    wheel = next((tmp_path / "dist").glob("visualenv-*.whl"))
    # the specs and the physics specs of specs/mujoco/ and specs/dmc/, by their paths under specs/
    bundled = sorted(
        p.relative_to(ROOT / "specs").as_posix()
        for p in [*(ROOT / "specs").glob("*"), *(ROOT / "specs").glob("mujoco/*"), *(ROOT / "specs").glob("dmc/*")]
        if p.suffix in (".yaml", ".toml")
    )
    with zipfile.ZipFile(wheel) as archive:
        shipped = sorted(
            n[len("visualenv/specs/") :]
            for n in archive.namelist()
            if n.startswith("visualenv/specs/") and n.endswith((".yaml", ".toml"))
        )
        pinned = sorted(n for n in archive.namelist() if n.startswith("visualenv/specs/mujoco/assets/"))
        dmc = sorted(n for n in archive.namelist() if n.startswith("visualenv/specs/dmc/assets/"))
        archive.extractall(tmp_path / "site")
    assert shipped == bundled
    # the MJCF files the MuJoCo ports read, pinned, with Gymnasium's licence and where they come from
    assets = ROOT / "specs" / "mujoco" / "assets"
    assert pinned == sorted(f"visualenv/specs/mujoco/assets/{p.name}" for p in assets.iterdir() if p.is_file())
    # dm_control's MJCF files the DMC tasks read (the common assets they include too), with its licence
    dmc_assets = ROOT / "specs" / "dmc" / "assets"
    assert dmc == sorted(
        f"visualenv/specs/dmc/assets/{p.relative_to(dmc_assets).as_posix()}"
        for p in dmc_assets.rglob("*")
        if p.is_file() and "__pycache__" not in p.parts
    )
    # import the unpacked wheel, not the checkout, and look a spec up by id
    probe = "from visualenv.env.registration import resolve; print(resolve('Goalie-v0'))"
    out = subprocess.run(
        [sys.executable, "-c", probe],
        cwd=tmp_path,
        env={"PYTHONPATH": str(tmp_path / "site")},
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    assert out == str((tmp_path / "site" / "visualenv" / "specs" / "goalie.yaml").resolve())


def test_the_architecture_page_names_every_package_and_module():
    """docs/architecture.md's Packages section names each package (``scene/``) and module (``build.py``) it holds."""
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8").split("## Packages")[1].split("\n## ")[0]
    package = ROOT / "visualenv"
    files = [p for p in package.rglob("*.py") if "specs" not in p.relative_to(package).parts]
    packages = sorted({f"{p.parent.name}/" for p in files if p.name == "__init__.py" and p.parent != package})
    modules = sorted({p.name for p in files if p.name != "__init__.py"})
    missing = [name for name in packages + modules if f"`{name}`" not in text]
    assert packages and modules and not missing, f"docs/architecture.md's Packages section misses {missing}"


#: the house's limits: README is a manual a user reads through, and every clone carries every committed agent
#: (float16 safetensors, about 5.5 MB each; the packed pickles they replaced were 8 % smaller and could not load weights-only)
README_MAX_CHARS = 16_000
TRACKED_MAX_BYTES = 45_000_000


def test_readme_and_the_repository_stay_within_the_houses_limits():
    assert len((ROOT / "README.md").read_text(encoding="utf-8")) <= README_MAX_CHARS
    if not shutil.which("git") or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout: the tracked files are unknown")
    tracked = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout.split(b"\0")
    size = sum((ROOT / name.decode()).stat().st_size for name in tracked if name and (ROOT / name.decode()).is_file())
    assert size <= TRACKED_MAX_BYTES, f"tracked files hold {size / 1e6:.1f} MB, over {TRACKED_MAX_BYTES / 1e6:.0f} MB"


def test_import_visualenv_never_imports_stable_baselines3_or_torch():
    """The train extra is optional: `import visualenv` (and its vector envs) must work without it, and start fast."""
    import subprocess
    import sys

    code = (
        "import sys, visualenv, visualenv.env.batch, visualenv.env.sb3_vec; "
        "assert not {'stable_baselines3', 'torch'} & set(sys.modules), 'SB3 or torch imported'"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert result.returncode == 0, result.stderr
