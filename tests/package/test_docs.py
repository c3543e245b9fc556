"""The manual holds together: every relative link and anchor in README, docs/ and results/ resolves, every section the
code points users to exists, measurements live in records that say how they were made, and the pages that once grew
into lab notebooks stay within their size."""

from __future__ import annotations

import re
import unicodedata
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
RECORDS = ROOT / "results" / "benchmarks"
#: the pages a user reads through: the manual's size limits (lines), issue 48
PAGE_MAX_LINES = {"docs/performance.md": 350, "docs/physics.md": 300}

FENCE = re.compile(r"^(```|~~~).*?^\1", re.M | re.S)
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)|<(?:img|a)\b[^>]*?\b(?:src|href)=\"([^\"]+)\"")
HEADING = re.compile(r"^#{1,6}\s+(.+?)\s*#*\s*$", re.M)


def pages() -> list[Path]:
    """Every Markdown page of the repository's manual and records."""
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "results").rglob("*.md"))]


def prose(path: Path) -> str:
    """A page without its fenced code blocks (their text is code, not links or headings)."""
    return FENCE.sub("", path.read_text(encoding="utf-8"))


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: its text without markup, lower case, punctuation dropped, spaces as hyphens."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link keeps its text
    text = text.replace("`", "").replace("*", "").strip().lower()
    kept = "".join(c for c in text if c in " -_" or unicodedata.category(c)[0] in "LNM")
    return kept.replace(" ", "-")


def headings(path: Path) -> list[str]:
    return HEADING.findall(prose(path))


def anchors(path: Path) -> set[str]:
    """A page's anchors as GitHub makes them, a repeated heading's with -1, -2, ..."""
    seen: dict[str, int] = {}
    found = set()
    for heading in headings(path):
        base = slug(heading)
        found.add(base if base not in seen else f"{base}-{seen[base]}")
        seen[base] = seen.get(base, 0) + 1
    return found


def test_slugs_follow_githubs_rule():
    assert slug("Gymnasium, reproduced") == "gymnasium-reproduced"
    assert slug("RLlib runners against SubprocVecEnv") == "rllib-runners-against-subprocvecenv"
    assert slug("Seeds: selection and report on disjoint episodes") == "seeds-selection-and-report-on-disjoint-episodes"
    assert slug("Shipped agents reproduce on any x86-64 CPU") == "shipped-agents-reproduce-on-any-x86-64-cpu"
    assert slug("Actors (bindings)") == "actors-bindings"
    assert slug("A camera that zooms: `lens`") == "a-camera-that-zooms-lens"


@pytest.mark.parametrize("page", pages(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_relative_link_and_anchor_resolves(page: Path):
    broken = []
    for match in LINK.finditer(prose(page)):
        target = match.group(1) or match.group(2)
        if re.match(r"[a-z][a-z0-9+.-]*:", target):  # https:, mailto:: not this repository's
            continue
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if not file.exists():
            broken.append(f"{target}: no such file")
        elif anchor and file.suffix == ".md" and anchor not in anchors(file):
            broken.append(f"{target}: no heading with that anchor in {file.relative_to(ROOT)}")
    assert not broken, f"{page.relative_to(ROOT)}: {broken}"


def code_files() -> list[Path]:
    return [*ROOT.glob("visualenv/**/*.py"), *ROOT.glob("benchmarks/*.py"), *ROOT.glob("tests/*.py"), ROOT / "Makefile"]


def test_the_sections_the_code_points_to_exist():
    """Messages and docstrings send users to a page's anchor (`#which-device`) or name its section (`*On a GPU*`)."""
    cited, broken = 0, []
    for file in code_files():
        text = file.read_text(encoding="utf-8")
        for page, anchor in re.findall(r"docs/([\w-]+\.md)#([\w-]+)", text):
            cited += 1
            if not (ROOT / "docs" / page).exists() or anchor not in anchors(ROOT / "docs" / page):
                broken.append(f"{file.relative_to(ROOT)}: docs/{page}#{anchor}")
        for page, starred, quoted in re.findall(r"docs/([\w-]+\.md),\s+(?:\*([^*\n]+)\*|'([^'\n]+)')", text):
            cited += 1
            name = starred or quoted
            if not (ROOT / "docs" / page).exists() or not any(
                h.startswith(name) for h in headings(ROOT / "docs" / page)
            ):
                broken.append(f"{file.relative_to(ROOT)}: docs/{page}, {name!r}")
    assert cited >= 5 and not broken, broken


@pytest.mark.parametrize("page, limit", PAGE_MAX_LINES.items())
def test_the_manuals_pages_stay_within_their_size(page: str, limit: int):
    lines = len((ROOT / page).read_text(encoding="utf-8").splitlines())
    assert lines <= limit, f"{page} has {lines} lines, over {limit}: measurements go to results/benchmarks/ as records"


#: a measured figure: a time, a size, a share, a rate or a speed-up (not a count, a resolution or a version)
FIGURE = re.compile(r"\d[\d,.–-]*\s?(?:ms|µs|us|ns|s|MB|GB|%|(?:env[- ])?steps/s|samples/s)(?!\w)|\d\.\d+x(?!\w)")


def test_the_performance_page_keeps_its_figures_in_one_table_with_their_commands_and_records():
    """docs/performance.md is a manual: its prose says what to choose and why, and its figures stand in one table whose
    rows each give the command that reproduces them and the record they come from (issue 60)."""
    tables: list[list[str]] = []
    prose_figures = []
    previous = ""
    for line in prose(ROOT / "docs" / "performance.md").splitlines():
        if line.startswith("|"):
            if not previous.startswith("|"):
                tables.append([])
            tables[-1].append(line)
        elif FIGURE.search(re.sub(r"`[^`]*`", "", line)):
            prose_figures.append(line)
        previous = line
    assert not prose_figures, f"figures outside the table (move them to a record): {prose_figures}"
    with_figures = [t for t in tables if any(FIGURE.search(re.sub(r"`[^`]*`", "", row)) for row in t)]
    assert len(with_figures) == 1, f"{len(with_figures)} tables of figures, not one"
    rows = with_figures[0][2:]
    unsourced = [row for row in rows if "`" not in row or "results/benchmarks/" not in row]
    assert len(rows) >= 10 and not unsourced, f"rows without a command or a record: {unsourced}"


def test_every_benchmark_record_says_how_where_and_when_it_was_measured():
    """A record starts with its commands, the machine and the date; the index lists every file of the folder."""
    records = sorted(p for p in RECORDS.glob("*.md") if p.name != "README.md")
    assert len(records) >= 10
    for record in records:
        head = record.read_text(encoding="utf-8")[:2500]
        assert head.startswith("# "), record.name
        for part in ("Command", "Machine", "Date:"):
            assert re.search(rf"^{part}", head, re.M), f"{record.name} does not say {part!r} before its figures"
    index = (RECORDS / "README.md").read_text(encoding="utf-8")
    unlisted = [p.name for p in RECORDS.iterdir() if p.name != "README.md" and f"]({p.name})" not in index]
    assert not unlisted, f"results/benchmarks/README.md does not list {unlisted}"
