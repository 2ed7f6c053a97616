"""
The user docs hold together: links resolve, the README stays short, no development history.

Every relative link (and image) in README.md, BENCHMARKS.md and docs/*.md must name a file
of the repository, and a ``#fragment`` a heading of the target, by GitHub's rule for heading
anchors (lower case, punctuation dropped, spaces to hyphens, repeats numbered). Links inside
fenced code blocks and inline code are not links. The README stays within 250 lines (issue
26 item 7; the rest lives in docs/), and the user docs describe the product as it is: the
phrases that only make sense as a history of its development are refused.
"""
from __future__ import annotations

import re
from pathlib import Path
from urllib.parse import unquote

import pytest

from conftest import ROOT

#: The user documentation: what a reader of the repository opens.
DOCS = [ROOT / "README.md", ROOT / "BENCHMARKS.md", *sorted((ROOT / "docs").glob("*.md"))]
#: [text](target) and ![alt](target); the target ends at whitespace or the closing bracket.
LINK = re.compile(r"!?\[(?:[^\]\\]|\\.)*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
#: A URL scheme (http:, https:, mailto:, ...): not a file of the repository.
SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")
#: The pages checked for development history.
HISTORY_DOCS = [ROOT / "README.md", ROOT / "BENCHMARKS.md", *sorted((ROOT / "docs").glob("*.md"))]
#: Phrases that tell a development history rather than describe the product.
HISTORY = re.compile(r"\b(this stop|previous stop|stops? ago|until this stop|an earlier stop|"
                     r"issue \d+)\b", re.IGNORECASE)


def _prose(text: str) -> str:
    """Return ``text`` with fenced code blocks and inline code blanked (line count kept)."""
    out, fence = [], None
    for line in text.split("\n"):
        stripped = line.lstrip()
        marker = stripped[:3]
        if fence is None and marker in ("```", "~~~"):
            fence = marker
            out.append("")
        elif fence is not None:
            if stripped.startswith(fence):
                fence = None
            out.append("")
        else:
            out.append(re.sub(r"`[^`]*`", "``", line))
    return "\n".join(out)


def slug(heading: str) -> str:
    """
    Return GitHub's anchor of a heading: lower case, only word characters, hyphens, spaces.

    Inline code and emphasis markers go with the punctuation; spaces become hyphens.
    """
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip())  # a link: its text
    text = re.sub(r"[^\w\- ]", "", text.lower())
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Return every heading anchor of the Markdown file ``path`` (repeats numbered -1, -2)."""
    found: set[str] = set()
    seen: dict[str, int] = {}
    fence = None
    for line in path.read_text(encoding="utf-8").split("\n"):
        stripped = line.lstrip()
        if fence is None and stripped[:3] in ("```", "~~~"):
            fence = stripped[:3]
            continue
        if fence is not None:
            if stripped.startswith(fence):
                fence = None
            continue
        match = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if match:
            base = slug(match.group(1))
            count = seen.get(base, 0)
            seen[base] = count + 1
            found.add(base if count == 0 else f"{base}-{count}")
    return found


def links(path: Path) -> list[tuple[int, str]]:
    """Return (line number, target) of every relative link and image in ``path``."""
    found = []
    for number, line in enumerate(_prose(path.read_text(encoding="utf-8")).split("\n"), 1):
        for match in LINK.finditer(line):
            target = match.group(1)
            if not SCHEME.match(target):
                found.append((number, target))
    return found


def broken(path: Path, root: Path = ROOT) -> list[str]:
    """Return a line ``file:line: target: problem`` for every link of ``path`` that fails."""
    problems = []
    for number, target in links(path):
        where = f"{path.relative_to(root)}:{number}: {target}"
        file_part, _, fragment = target.partition("#")
        dest = (path.parent / unquote(file_part)).resolve() if file_part else path
        if not dest.exists():
            problems.append(f"{where}: no such file")
            continue
        try:
            dest.relative_to(root)
        except ValueError:
            problems.append(f"{where}: outside the repository")
            continue
        if fragment and dest.suffix == ".md" and unquote(fragment) not in anchors(dest):
            problems.append(f"{where}: no heading with anchor #{fragment} in "
                            f"{dest.relative_to(root)}")
    return problems


def test_every_relative_link_of_the_docs_resolves():
    """Each link of README.md, BENCHMARKS.md and docs/*.md names a file, and a heading of it."""
    checked = sum(len(links(path)) for path in DOCS)
    assert checked >= 30, f"only {checked} links found: is the link pattern still right?"
    problems = [line for path in DOCS for line in broken(path)]
    assert not problems, "broken links:\n" + "\n".join(problems)


def test_a_broken_link_and_a_missing_anchor_are_found(tmp_path):
    """The checker itself: a missing file and a missing heading are reported, code is not."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "README.md").write_text("# Read me\n", encoding="utf-8")
    page = tmp_path / "docs" / "probe.md"
    page.write_text("# Probe\n\n## Two words `code`\n\n[ok](#two-words-code) [top](#probe)\n"
                    "[file](../README.md) [gone](missing.md) [anchor](../README.md#no-such)\n"
                    "`[in code](missing_too.md)`\n```\n[fenced](missing_three.md)\n```\n",
                    encoding="utf-8")
    problems = broken(page, tmp_path)
    assert len(problems) == 2, problems
    assert "missing.md: no such file" in problems[0]
    assert "no heading with anchor #no-such in README.md" in problems[1]


@pytest.mark.parametrize("heading, anchor", [
    ("Mechanisms in space (`space: 3d`)", "mechanisms-in-space-space-3d"),
    ("Several drives and outputs; the XY stage", "several-drives-and-outputs-the-xy-stage"),
    ("Hinges from their own geometry: finite elements", "hinges-from-their-own-geometry-finite-"
     "elements"),
    ("6×6 hinge stiffness", "66-hinge-stiffness"),
])
def test_anchors_follow_githubs_rule(heading, anchor):
    """Anchors by GitHub's rule: inline code's text kept, ``:``, ``;``, ``(``, ``×`` dropped."""
    assert slug(heading) == anchor


def test_the_readme_stays_short():
    """The README is the entry point: at most 250 lines, the rest in docs/."""
    lines = (ROOT / "README.md").read_text(encoding="utf-8").count("\n")
    assert lines <= 250, f"README.md has {lines} lines; move sections to docs/"


def test_the_docs_tell_no_development_history():
    """No 'this stop', 'the previous stop', 'issue N' in README and docs/: the product as it is."""
    found = [f"{path.relative_to(ROOT)}:{number}: {match.group(0)!r}"
             for path in HISTORY_DOCS
             for number, line in enumerate(path.read_text(encoding="utf-8").split("\n"), 1)
             for match in HISTORY.finditer(line)]
    assert not found, "development history in the user docs:\n" + "\n".join(found)
