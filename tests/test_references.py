"""Every reference in the repository resolves inside the repository.

Scanned: the text files of agent/, sim/, tools/ and tests/, docs/*.md, README.md,
CHANGELOG.md (when present) and the build files (Dockerfile, docker-compose.yml,
Makefile, pyproject.toml, .ci/). A file fails, listing ``file:line``, on:

* a design reference not of the form ``docs/design.md §N`` (also ``§N–M`` and
  ``§N, §M``) with N a ``## N.`` section of docs/design.md; inside docs/design.md a bare
  ``§N`` must name one of its sections;
* an issue-tracker reference: ``issue N``, ``issue #N``, ``(#N)`` or ``#N``: the reason
  belongs in words, the tracker is not in the repository;
* a paper section ("NAO paper 4.1.2", "NAO 4.1.1", "AUV III.B.2.a", "AUV paper §II",
  ranges such as "4.1.2–4.2" or "III.B–C") that docs/papers.md does not list, or an
  equation number ("eq. 9", "AUV eqs. 5–7") that it does not list;
* a relative markdown link in docs/*.md, README.md or CHANGELOG.md to a file that does
  not exist, or to an anchor that is no heading of the linked page.

The checks are plain functions of a text, so the negative tests feed them synthetic
texts (this file itself is therefore not scanned). One test per scanned group of files
keeps the failures apart.
"""

from __future__ import annotations

import re
import unicodedata
from collections.abc import Iterator, Set
from functools import cache, lru_cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DESIGN = ROOT / "docs" / "design.md"
PAPERS = ROOT / "docs" / "papers.md"
#: This file: its negative tests hold every kind of bad reference on purpose.
SELF = Path(__file__).resolve()

TEXT_SUFFIXES = {".py", ".md", ".js", ".html", ".css", ".toml", ".sh", ".yml", ".yaml", ".txt"}
BUILD_FILES = ("Dockerfile", "docker-compose.yml", "Makefile", "pyproject.toml")

#: Whitespace that may run over a line break, with the next line's comment marker.
_WS = r"(?:[ \t]|\n[ \t]*(?:#:?|//)?[ \t]*)"
_SEC = r"§[ \t]?(\d+)(?:[–-](\d+))?"

Finding = tuple[int, str]
_ASCII_LOWER = str.maketrans("ABCDEFGHIJKLMNOPQRSTUVWXYZ", "abcdefghijklmnopqrstuvwxyz")


def _line(text: str, pos: int) -> int:
    return text.count("\n", 0, pos) + 1


@lru_cache(maxsize=4)
def _lower(text: str) -> str:
    """``text`` in lower case, position for position (``str.lower`` may lengthen a few
    letters, such as "İ"; then only ASCII is lowered)."""
    low = text.lower()
    return low if len(low) == len(text) else text.translate(_ASCII_LOWER)


def _at(pattern: re.Pattern[str], text: str, literal: str) -> Iterator[re.Match[str]]:
    """``pattern.match`` wherever ``literal`` (lower case) starts a word of ``text``: a
    string search finds the candidates, so a scan of the repository stays fast."""
    hay = _lower(text)
    pos = hay.find(literal)
    while pos >= 0:
        before = text[pos - 1] if pos else " "
        if not (before.isalnum() or before == "_"):
            m = pattern.match(text, pos)
            if m:
                yield m
        pos = hay.find(literal, pos + 1)


def _fenced(text: str) -> str:
    """``text`` with the lines of fenced code blocks blanked (line numbers kept)."""
    out, fence = [], False
    for line in text.split("\n"):
        if line.lstrip().startswith("```"):
            fence = not fence
            out.append("")
        else:
            out.append("" if fence else line)
    return "\n".join(out)


# --------------------------------------------------------------------------- design


def design_sections(text: str) -> set[int]:
    """The numbers N of the ``## N. Title`` headings of a design page."""
    return {int(m.group(1)) for m in re.finditer(r"^## (\d+)\. ", _fenced(text), re.M)}


_DESIGN_REF = re.compile(rf"design\.md{_WS}*{_SEC}(?:{_WS}*(?:,|and|;){_WS}*{_SEC})*", re.I)


def design_refs(text: str, sections: Set[int], *, own: bool = False) -> list[Finding]:
    """Design references that are not ``docs/design.md §N`` with N in ``sections``.

    ``own``: the text is docs/design.md itself, whose bare ``§N`` name its sections.
    """
    found: list[Finding] = []
    for m in _at(_DESIGN_REF, text, "design.md"):
        line = _line(text, m.start())
        at = m.start()
        before = text[at - 6] if at >= 6 else " "
        canonical = text[at - 5 : at + 9] == "docs/design.md" and not (
            before.isalnum() or before in "./_-"
        )
        if not canonical:
            found.append((line, f"{m.group(0)!r}: cite it as docs/design.md §N"))
        for a, b in re.findall(_SEC, m.group(0)):
            for n in (a, b):
                if n and int(n) not in sections:
                    found.append((line, f"docs/design.md has no §{n}"))
    for m in re.finditer(r"DESIGN\.md(?!\s*§)", text):
        found.append((_line(text, m.start()), "DESIGN.md: the design is docs/design.md"))
    if own:
        for m in re.finditer(_SEC, text):
            for n in m.groups():
                if n and int(n) not in sections:
                    found.append((_line(text, m.start()), f"no §{n} in this page"))
    return found


# --------------------------------------------------------------------------- tracker

_ISSUE = re.compile(rf"issues?{_WS}*#?[ \t]?\d+\b", re.I)  # issue 21, issue #9, Issue\n# 21
_HASH = re.compile(r"\((?:#\d+(?:,\s*)?)+\)|#\d{1,2}(?![\w-])")  # (#9), (#9, #20), #9
#: Characters before a ``#`` that make it no reference: a heading's ``##``, a string
#: literal's ``"#0 1.00 m``, an HTML entity, a link's ``(#1-phases`` is kept out by the
#: ``-`` after the number, and 3-digit hex colours (``#888``) by the digit count.
#: History that belongs in git: "try 7", "tries 9 and 10", "the tenth session" (not
#: "a second session": zenoh sessions are one of the project's words).
_HISTORY = re.compile(
    r"\btr(?:y|ies)[ \t]+\d+\b|\b(?:third|fourth|fifth|sixth|seventh|eighth|ninth|tenth"
    r"|eleventh|twelfth)[ \t]+session\b",
    re.I,
)
_NOT_BEFORE_HASH = set("&/#\"'`]") | {"_"}


def tracker_refs(text: str) -> list[Finding]:
    """Issue-tracker references: ``issue N``, ``issue #N``, ``(#N)``, ``#N``; and the
    history of how work went (``try N``, ``the tenth session``): git keeps that."""
    lines: dict[int, str] = {}
    for m in _at(_ISSUE, text, "issue"):
        lines.setdefault(_line(text, m.start()), m.group(0))
    for m in _HISTORY.finditer(text):
        lines.setdefault(_line(text, m.start()), m.group(0))
    pos = text.find("#")
    while pos >= 0:
        start = pos - 1 if pos and text[pos - 1] == "(" else pos
        before = text[start - 1] if start else " "
        if not (before.isalnum() or before in _NOT_BEFORE_HASH):
            ref = _HASH.match(text, start) or _HASH.match(text, pos)
            if ref:
                lines.setdefault(_line(text, pos), ref.group(0))
        pos = text.find("#", pos + 1)
    return [(line, f"{ref!r}: say the reason in words") for line, ref in sorted(lines.items())]


# --------------------------------------------------------------------------- papers

Keys = tuple[frozenset[str], frozenset[str], frozenset[str], frozenset[str]]


@cache
def paper_keys() -> Keys:
    """NAO sections, AUV sections, NAO equations and AUV equations listed in papers.md."""
    return paper_keys_of(PAPERS.read_text(encoding="utf-8"))


def paper_keys_of(text: str) -> Keys:
    cells = re.findall(r"^\| ([^|]+?) \|", text, re.M)
    nao = {c[4:] for c in cells if re.fullmatch(r"NAO \d+(\.\d+)*", c)}
    auv = {c[4:] for c in cells if re.fullmatch(r"AUV [IVX]+(\.[A-Z](\.\d+(\.[a-z])?)?)?", c)}
    nao_eq: set[str] = set()
    auv_eq: set[str] = set()
    for c in cells:
        m = re.fullmatch(r"(AUV )?eqs?\. (\d+)(?:–(\d+))?", c)
        if m:
            lo, hi = int(m.group(2)), int(m.group(3) or m.group(2))
            (auv_eq if m.group(1) else nao_eq).update(str(k) for k in range(lo, hi + 1))
    return frozenset(nao), frozenset(auv), frozenset(nao_eq), frozenset(auv_eq)


_NAO_NUM = r"[1-9]\d*(?:\.\d+)*"
_NAO_REF = re.compile(
    rf"NAO(?:{_WS}+paper)?(?P<sec>{_WS}+section|{_WS}*§)?{_WS}*(?P<x>{_NAO_NUM})"
    rf"(?:[–-](?P<y>{_NAO_NUM}))?(?![\d.]*{_WS}*(?:m|cm|mm|s|%|°|kg)\b)"
)
_AUV_NUM = r"[IVX]+(?:\.[A-Z](?:\.\d+(?:\.[a-z])?)?)?"
_AUV_REF = re.compile(
    rf"AUV(?:{_WS}+paper)?{_WS}*§?{_WS}*(?P<x>{_AUV_NUM})\b(?:[–-](?P<y>[IVX]+|[A-Z])\b)?"
)
_EQ_REF = re.compile(rf"eqs?\.{_WS}*(?P<a>\d+)(?:[–-](?P<b>\d+))?", re.I)


def _auv_end(x: str, y: str) -> str:
    """The other end of an AUV range: ``III.B–C`` → ``III.C``, ``I–II`` → ``II``."""
    if "." in x and re.fullmatch(r"[A-Z]", y) and not re.fullmatch(r"[IVX]+", y):
        return x.split(".")[0] + "." + y
    return y


def paper_refs(text: str, keys: Keys | None = None) -> list[Finding]:
    """Paper sections and equations that docs/papers.md does not list."""
    nao, auv, nao_eq, auv_eq = keys if keys is not None else paper_keys()
    found: list[Finding] = []
    for m in _at(_NAO_REF, text, "nao"):
        # a bare "NAO 2" is a robot's name: only "NAO paper x", "NAO §x" and "NAO x.y"
        if "paper" in m.group(0) or m.group("sec") or "." in m.group("x"):
            for x in filter(None, (m.group("x"), m.group("y"))):
                if x not in nao:
                    found.append((_line(text, m.start()), f"NAO paper {x}: not in docs/papers.md"))
    for m in _at(_AUV_REF, text, "auv"):
        x, y = m.group("x"), m.group("y")
        for sec in filter(None, (x, y and _auv_end(x, y))):
            if sec not in auv:
                found.append((_line(text, m.start()), f"AUV {sec}: not in docs/papers.md"))
    for m in _at(_EQ_REF, text, "eq"):
        lo, hi = int(m.group("a")), int(m.group("b") or m.group("a"))
        is_auv = re.search(rf"AUV{_WS}+$", text[max(0, m.start() - 8) : m.start()])
        known = auv_eq if is_auv else nao_eq | auv_eq
        if hi < lo or any(str(k) not in known for k in range(lo, hi + 1)):
            found.append((_line(text, m.start()), f"{m.group(0)!r}: not in docs/papers.md"))
    return found


# --------------------------------------------------------------------------- links


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces → '-'."""
    text = re.sub(r"[`*]|<[^>]+>", "", heading.strip()).lower()
    keep = (c for c in text if c in " -_" or unicodedata.category(c)[0] in "LN")
    return "".join(keep).replace(" ", "-")


@cache
def anchors(path: Path) -> frozenset[str]:
    text = _fenced(path.read_text(encoding="utf-8"))
    out: set[str] = set()
    for h in re.findall(r"^#{1,6} (.+?)#*\s*$", text, re.M):
        s, k = slug(h), 1
        while s in out:
            s = f"{slug(h)}-{k}"
            k += 1
        out.add(s)
    return frozenset(out)


def link_refs(path: Path, text: str) -> list[Finding]:
    """Relative links of a markdown page to files, or anchors, that do not exist."""
    found: list[Finding] = []
    clean = _fenced(text)
    clean = re.sub(r"`[^`\n]*`", lambda m: " " * len(m.group(0)), clean)
    for m in re.finditer(r"!?\[[^\[\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)", clean):
        target = m.group(1)
        if re.match(r"[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        file_part, _, anchor = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path
        line = _line(clean, m.start())
        if not dest.exists():
            found.append((line, f"{target}: no such file"))
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            found.append((line, f"{target}: no such heading in {dest.name}"))
    return found


# --------------------------------------------------------------------------- scan


def _scanned() -> dict[str, list[Path]]:
    groups: dict[str, list[Path]] = {}
    for top in ("agent", "sim", "tools", "tests"):
        groups[top] = sorted(
            p
            for p in (ROOT / top).rglob("*")
            if p.is_file()
            and p.suffix in TEXT_SUFFIXES
            and "__pycache__" not in p.parts
            and p != SELF
        )
    for p in sorted((ROOT / "docs").glob("*.md")):
        groups[f"docs/{p.name}"] = [p]
    for name in ("README.md", "CHANGELOG.md"):
        if (ROOT / name).exists():
            groups[name] = [ROOT / name]
    build = [ROOT / n for n in BUILD_FILES if (ROOT / n).exists()]
    build += sorted(p for p in (ROOT / ".ci").glob("*") if p.is_file())
    groups["build files"] = build
    return groups


GROUPS = _scanned()


@cache
def _sections() -> frozenset[int]:
    return frozenset(design_sections(DESIGN.read_text(encoding="utf-8")))


def findings(path: Path) -> list[str]:
    text = path.read_text(encoding="utf-8")
    rel = path.relative_to(ROOT).as_posix()
    found = design_refs(text, _sections(), own=path == DESIGN)
    found += tracker_refs(text if path.suffix != ".md" else _fenced(text))
    if path != PAPERS:
        found += paper_refs(text)
    if path.suffix == ".md" and (path.parent == ROOT / "docs" or path.parent == ROOT):
        found += link_refs(path, text)
    return [f"{rel}:{line}: {msg}" for line, msg in sorted(found)]


@pytest.mark.parametrize("group", sorted(GROUPS))
def test_every_reference_resolves(group: str) -> None:
    bad = [f for path in GROUPS[group] for f in findings(path)]
    assert not bad, f"{len(bad)} unresolved reference(s):\n" + "\n".join(bad)


def test_the_scan_covers_the_repository() -> None:
    assert {"agent", "sim", "tools", "tests", "README.md", "docs/design.md"} <= set(GROUPS)
    assert ROOT / "tests" / "test_layers.py" in GROUPS["tests"]
    assert len(GROUPS["agent"]) > 50


# --------------------------------------------------------------------------- negative

SECTIONS = {1, 2, 3, 9, 10}
KEYS = paper_keys_of(
    "| NAO 4.1.2 | x |\n| NAO 4.2 | x |\n| NAO 5.2.2 | x |\n| AUV II | x |\n"
    "| AUV III.B | x |\n| AUV III.C | x |\n| AUV III.B.2.a | x |\n"
    "| eq. 9 | x |\n| eqs. 12–13 | x |\n| AUV eq. 5 | x |\n| AUV eqs. 6–7 | x |\n"
)


def test_design_references_of_the_old_brief_are_caught() -> None:
    text = "a\n(DESIGN.md §9)\nb (docs/design.md §3, §8)\nc docs/design.md §1–3\n"
    got = design_refs(text, SECTIONS)
    assert (2, "'DESIGN.md §9': cite it as docs/design.md §N") in got
    assert (3, "docs/design.md has no §8") in got
    assert not [f for f in got if f[0] == 4]
    assert design_refs("see docs/design.md\n§11 and the rest", SECTIONS) == [
        (1, "docs/design.md has no §11")
    ]
    assert design_refs("# Design.md §2 lower\n", SECTIONS)[0][0] == 1
    assert design_refs("bare §4 here (§9)", SECTIONS, own=True) == [(1, "no §4 in this page")]
    assert design_refs("the paper's §4.1 and RFC 5280 §5", SECTIONS) == []


def test_tracker_references_are_caught() -> None:
    text = (
        "fine line\n(issue 21: at 50 NAOs)\nIssue #9. Before\nsee (#12)\n"
        "a fix for #7 here\nwrapped issue\n# 20 here\n(#9 and more\n"
        'color: #888; label "#0 1.00 m"; [a](#1-phases) ## 3. Heading\n'
    )
    lines = [line for line, _ in tracker_refs(text)]
    assert lines == [2, 3, 4, 5, 6, 8]


def test_history_in_the_text_is_caught() -> None:
    text = (
        "a 100-NAO run (try 8)\nIn tries 9 and 10 the pair\nthe lookahead (eighth session)\n"
        "a second session of a claimed key\nthe zenoh session opens\nthe agent tries each key\n"
    )
    assert [line for line, _ in tracker_refs(text)] == [1, 2, 3]


def test_paper_references_not_in_the_bibliography_are_caught() -> None:
    good = (
        "NAO paper 4.1.2, Algorithm 2, eq. 9; NAO paper 4.1.2–4.2; AUV III.B–C; AUV paper §II;\n"
        "AUV III.B.2.a; NAO 5.2.2 (iii) step 7; eqs. 12–13; AUV eqs. 5-7; a NAO 0.6 m ahead;\n"
        "NAO 2 yaw; NAO paper\n4.2\n"
    )
    assert paper_refs(good, KEYS) == []
    bad = "NAO paper §3.3\nNAO 4.1.1 x\nAUV III.D\nAUV III.B–D\neq. 14\nAUV eq. 9\nNAO paper 4.2–4.4\n"
    assert sorted(line for line, _ in paper_refs(bad, KEYS)) == [1, 2, 3, 4, 5, 6, 7]


def test_links_to_missing_files_and_headings_are_caught(tmp_path: Path) -> None:
    (tmp_path / "other.md").write_text("# Other page\n\n## Fleet size: 10 NAOs (x)\n")
    page = tmp_path / "page.md"
    text = (
        "[ok](other.md) [ok](other.md#fleet-size-10-naos-x) [ok](#a-heading)\n"
        "[gone](missing.md) ![gone](img/none.png)\n"
        "[bad anchor](other.md#fleet-size-10-naos-issue-21) [web](https://example.org/x)\n"
        "`[code](nowhere.md)`\n```\n[fenced](nowhere.md)\n```\n# A heading\n"
    )
    page.write_text(text)
    assert [line for line, _ in link_refs(page, text)] == [2, 2, 3]


def test_github_slugs() -> None:
    assert (
        slug("7. Frames without the papers' alignment") == "7-frames-without-the-papers-alignment"
    )
    assert slug("Fleet size: 10, 30, 50 and 100 NAOs (x)") == "fleet-size-10-30-50-and-100-naos-x"
    assert slug("`tools.plan` and the rest") == "toolsplan-and-the-rest"
