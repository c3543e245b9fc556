"""Every use of a dependency's internals lives in visualenv/compat/: the package is searched for them."""

from __future__ import annotations

import io
import re
import tokenize
from pathlib import Path

PACKAGE = Path(__file__).parents[1] / "visualenv"
#: names that reach past a dependency's documented API: C calls through ctypes, glibc's allocator, frame inspection
INTERNAL_NAMES = {"ctypes", "CDLL", "cdll", "cffi", "mallopt", "malloc_trim", "_getframe", "currentframe", "getouterframes", "f_locals", "f_back"}
#: MKL's service functions (mkl_cbwr_set, mkl_serv_cbwr_get, ...), by name or looked up by a string
MKL_SERVICE = re.compile(r"^mkl_\w+$")
#: files that still hold such uses, with the change that removes them (made on another branch): each entry must still be
#: true, so the list shrinks as those branches are merged and this test then names the entry to remove
PENDING: dict[str, str] = {}


def internal_uses(text: str, name: str) -> list[str]:
    """`name:line: word` for each use in code (names and plain strings; comments and docstrings are prose)."""
    uses = []
    tokens = tokenize.generate_tokens(io.StringIO(text).readline)
    for token in tokens:
        if token.type == tokenize.NAME:
            word = token.string
        elif token.type == tokenize.STRING and re.fullmatch(r"[rbuRBU]?(['\"])\w+\1", token.string):
            word = token.string.strip("rbuRBU")[1:-1]
        else:
            continue
        if word in INTERNAL_NAMES or MKL_SERVICE.match(word):
            uses.append(f"{name}:{token.start[0]}: {word}")
    return uses


def test_dependency_internals_are_used_only_in_the_compat_package():
    outside = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        relative = path.relative_to(PACKAGE).as_posix()
        if relative.startswith("compat/"):
            continue
        uses = internal_uses(path.read_text(encoding="utf-8"), relative)
        if uses:
            outside[relative] = uses
    unexpected = {name: uses for name, uses in outside.items() if name not in PENDING}
    assert not unexpected, "move these into visualenv/compat/ (one module per dependency):\n" + "\n".join(
        use for uses in unexpected.values() for use in uses)
    fixed = sorted(set(PENDING) - set(outside))
    assert not fixed, f"no longer uses a dependency's internals: remove it from PENDING: {fixed}"


def test_the_search_finds_what_it_looks_for():
    """The search itself: each kind of use is found in code, and prose about them is not."""
    text = ('"""ctypes and mallopt are named in prose."""\n'
            "import ctypes  # a comment naming malloc_trim\n"
            "frame = sys._getframe(1)\n"
            "lib = getattr(torch_lib, 'mkl_serv_cbwr_set')\n")
    assert internal_uses(text, "sample.py") == ["sample.py:2: ctypes", "sample.py:3: _getframe", "sample.py:4: mkl_serv_cbwr_set"]
