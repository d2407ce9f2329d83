"""The documentation stands alone: its links resolve, it names no file outside the repository.

* Every relative link and image in README.md, docs/*.md, notebooks/README.md and the
  notebooks' markdown cells points to a file of the repository, and an anchor
  (``page.md#heading``) to a heading of that page (GitHub's heading slugs).
* Every repository path a page writes as code (`systems/flexiforce.py`) exists.
* Every citation of docs/evidence/paper-notes.md by section number names a section it has.
* No tracked file names a file outside the repository (the shared folder of the team that
  wrote it, its design or style notes) or a tracker's issue number.
* The README is a landing page: under 210 lines.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
PAPER_NOTES = ROOT / "docs" / "evidence" / "paper-notes.md"
# The README is a landing page of about 150-200 lines; the findings live under docs/.
README_MAX_LINES = 210

_FENCE = re.compile(r"^(```|~~~).*?^\1[^\n]*$", re.M | re.S)
_CODE_SPAN = re.compile(r"`([^`\n]+)`")
# [text](target) and ![alt](target); the target ends at the first space or ")".
_LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_HEADING = re.compile(r"^#{1,6}\s+(.+?)\s*#*\s*$", re.M)
# A path into the repository written as code: a top-level folder, then a file or folder.
_REPO_PATH = re.compile(r"^(?:systems|diagrams|urdf|docs|notebooks|tests|\.ci)/[\w./-]*")
# Citations "docs/evidence/paper-notes.md, section 4", "paper-notes.md §2", "sections 4 and 5".
_NOTES_CITATION = re.compile(
    r"paper-notes\.md\)?[\s,)\]`]*(?:§\s*|sections?\s+)(\d+(?:\s*(?:,|and|to)\s*\d+)*)"
)
# What the repository must not name. Written so that this file does not match itself.
_OUTSIDE = {
    "the shared folder": re.compile(r"\.\./shared"),
    "the design notes": re.compile(r"\bdesign\.md\b"),
    "the style notes": re.compile(r"\bstyle\.md\b"),
    "an issue number": re.compile(r"\bissues?\s*#?\d+", re.I),
}


def _markdown_pages() -> list[Path]:
    """Every page: the README, every page under docs/ (guide, reference, evidence), the
    notebooks' and the URDF's READMEs."""
    pages = sorted((ROOT / "docs").rglob("*.md"))
    return [README, *pages, ROOT / "notebooks" / "README.md", ROOT / "urdf" / "README.md"]


def _notebooks() -> list[Path]:
    return sorted((ROOT / "notebooks").glob("*.ipynb"))


def _markdown_of(path: Path) -> str:
    """The markdown text of a page, or of a notebook's markdown cells."""
    if path.suffix == ".ipynb":
        cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
        return "\n\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "markdown")
    return path.read_text(encoding="utf-8")


def _prose(markdown: str) -> str:
    """The markdown without its fenced code blocks."""
    return _FENCE.sub("", markdown)


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link's text only
    return re.sub(r"[^\w\- ]", "", text.strip().lower()).replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    anchors: set[str] = set()
    for heading in _HEADING.findall(_prose(page.read_text(encoding="utf-8"))):
        slug = _slug(heading)
        duplicate = 1
        unique = slug
        while unique in anchors:  # GitHub numbers repeated headings: slug, slug-1, ...
            unique = f"{slug}-{duplicate}"
            duplicate += 1
        anchors.add(unique)
    return anchors


def _broken_links(page: Path) -> list[str]:
    broken = []
    without_code = _CODE_SPAN.sub("", _prose(_markdown_of(page)))
    for target in _LINK.findall(without_code):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I):  # https:, mailto:
            continue
        path_part, _, anchor = target.partition("#")
        resolved = (page.parent / path_part).resolve() if path_part else page
        if not resolved.is_relative_to(ROOT):
            broken.append(f"{target} (outside the repository)")
        elif not resolved.exists():
            broken.append(f"{target} (no such file)")
        elif anchor and resolved.suffix == ".md" and anchor not in _anchors(resolved):
            broken.append(f"{target} (no heading '#{anchor}' in {resolved.name})")
    return broken


def _tracked_files() -> list[Path]:
    """The repository's files: git's list in a checkout, else every file but build output."""
    git = shutil.which("git")
    if git and (ROOT / ".git").exists():
        listed = subprocess.run(
            [git, "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True
        ).stdout.decode()
        return [ROOT / name for name in listed.split("\0") if name and (ROOT / name).is_file()]
    skipped = {".git", ".venv", "results", "__pycache__", "build", "dist", ".pytest_cache"}
    return [
        path
        for path in ROOT.rglob("*")
        if path.is_file()
        and not skipped.intersection(path.relative_to(ROOT).parts)
        and not any(part.endswith(".egg-info") for part in path.parts)
    ]


def _text(path: Path) -> str | None:
    data = path.read_bytes()
    if b"\0" in data:
        return None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return None


@pytest.mark.parametrize(
    "page", _markdown_pages() + _notebooks(), ids=lambda p: str(p.relative_to(ROOT))
)
def test_every_relative_link_resolves(page):
    assert page.is_file(), f"{page.relative_to(ROOT)} is missing"
    assert _broken_links(page) == []


@pytest.mark.parametrize(
    "page", _markdown_pages() + _notebooks(), ids=lambda p: str(p.relative_to(ROOT))
)
def test_every_repository_path_written_as_code_exists(page):
    missing = []
    for span in _CODE_SPAN.findall(_prose(_markdown_of(page))):
        match = _REPO_PATH.match(span.strip())
        if match and not (ROOT / match.group(0).rstrip(".")).exists():
            missing.append(match.group(0))
    assert missing == []


def test_the_link_checker_sees_a_broken_link(tmp_path, monkeypatch):
    """The checks above can fail: a page with a missing file, a bad anchor, a path out."""
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "a.md").write_text("# Title\n\n## Two words\n")
    page = tmp_path / "README.md"
    page.write_text(
        "[ok](docs/a.md#two-words) ![gone](docs/missing.png) [bad](docs/a.md#nowhere)\n"
        "[out](../elsewhere.md) `[not a link](docs/missing.md)` [web](https://example.org)\n"
        "```\n[in a code block](docs/missing.md)\n```\n"
    )
    assert _broken_links(page) == [
        "docs/missing.png (no such file)",
        "docs/a.md#nowhere (no heading '#nowhere' in a.md)",
        "../elsewhere.md (outside the repository)",
    ]


def test_github_heading_slugs():
    assert (
        _slug("7. The FlexiForce A201 and its circuit") == "7-the-flexiforce-a201-and-its-circuit"
    )
    assert _slug("A real-time factor of 100 with noise") == "a-real-time-factor-of-100-with-noise"
    assert _slug("`admittance simulate`: one run") == "admittance-simulate-one-run"


def test_paper_notes_sections_cited_exist():
    numbered = {int(n) for n in re.findall(r"^## (\d+)\. ", PAPER_NOTES.read_text(), re.M)}
    # Sections 1-8 keep the numbers the code and the tests cite.
    assert set(range(1, 9)) <= numbered
    cited = {}
    for path in _tracked_files():
        text = _text(path)
        if text is None:
            continue
        for numbers in _NOTES_CITATION.findall(text):
            for number in map(int, re.findall(r"\d+", numbers)):
                cited.setdefault(number, str(path.relative_to(ROOT)))
    assert cited, "no file cites docs/evidence/paper-notes.md by section: the pattern is broken"
    assert {n: where for n, where in cited.items() if n not in numbered} == {}


def test_no_tracked_file_names_what_is_outside_the_repository():
    found = []
    for path in _tracked_files():
        text = _text(path)
        if text is None:
            continue
        for what, pattern in _OUTSIDE.items():
            for match in pattern.finditer(text):
                line = text.count("\n", 0, match.start()) + 1
                found.append(f"{path.relative_to(ROOT)}:{line}: {what} ({match.group(0)!r})")
    assert found == []


def test_the_checks_for_outside_names_match_what_they_should():
    # Assembled from pieces, so that this file itself names none of them.
    samples = {
        "the shared folder": "see " + ".." + "/shared/docs/notes",
        "the design notes": "as design" + ".md fixes it",
        "the style notes": "style" + ".md says",
        "an issue number": "fixed in Issue" + " #12, see issues" + " 3",
    }
    for what, sample in samples.items():
        assert _OUTSIDE[what].search(sample), what
    assert not any(p.search("an issue with 3 ports; designs.md") for p in _OUTSIDE.values())


def test_readme_is_a_landing_page():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) < README_MAX_LINES, f"README.md has {len(lines)} lines"
