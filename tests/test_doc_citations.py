"""Every citation of the design or the reference page resolves: the document is in the repository and
has a heading with the cited number (docs/design.md, docs/reference.md; "## N. Title").

Citations are found in the package, the jobs, the tests, the configs and the top-level docs pages, in
any of the forms the code has used: the page with or without ``docs/`` and ``.md``, then ``§``, "item"
or "section" (or nothing) and a number, or a range of numbers ("§6-9": each must exist). Pure text:
nothing is imported or run.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = {"design": ROOT / "docs" / "design.md", "reference": ROOT / "docs" / "reference.md"}
SCANNED = ("fmctd_dist", "jobs", "tests", "configs")  # searched recursively; docs/*.md beside them
SUFFIXES = {".py", ".yaml", ".yml", ".sh", ".md", ".txt", ".toml"}
# Pages whose old citations are not kept up to date: the results page (text being moved out of it) and
# the lab notebook (history, cites the design as it was then).
SKIPPED = ("docs/results.md", "docs/notebook/")

SECTION = "\u00a7"
CITATION = re.compile(
    r"\b(?:docs/)?(design|reference)(?:\.md)?`*\s*(?:item\s+|section\s+|" + SECTION + r"\s*)?"
    r"(\d+)\b(?:\s*[-\u2013]\s*(\d+)\b)?",
    re.IGNORECASE,
)
HEADING = re.compile(r"^#{1,6}\s+(\d+)\.", re.MULTILINE)


def citations(text: str) -> list[tuple[int, str, list[int]]]:
    """(line, document key, cited section numbers) of every citation in ``text``."""
    out = []
    for m in CITATION.finditer(text):
        lo = int(m.group(2))
        hi = int(m.group(3)) if m.group(3) else lo
        out.append((text.count("\n", 0, m.start()) + 1, m.group(1).lower(), list(range(lo, max(lo, hi) + 1))))
    return out


def sections(path: Path) -> set[int]:
    """The numbers of a page's numbered headings ("## 7. Results" -> 7)."""
    return {int(n) for n in HEADING.findall(path.read_text())}


def scanned_files(root: Path = ROOT) -> list[Path]:
    files = [p for d in SCANNED for p in (root / d).rglob("*") if p.is_file() and p.suffix in SUFFIXES]
    files += sorted((root / "docs").glob("*.md"))
    rel = [(p, p.relative_to(root).as_posix()) for p in files]
    return sorted(p for p, r in rel if not any(r == s or r.startswith(s) for s in SKIPPED))


def broken(files: list[Path], docs: dict[str, Path], root: Path = ROOT) -> list[str]:
    """One line per citation whose document is missing or has no heading with the cited number."""
    have = {key: sections(path) if path.is_file() else None for key, path in docs.items()}
    out = []
    for f in files:
        for line, key, numbers in citations(f.read_text(errors="replace")):
            where = f"{f.relative_to(root).as_posix()}:{line}"
            if have[key] is None:
                out.append(f"{where}: cites {key} but {docs[key].relative_to(root).as_posix()} is not in the repo")
                continue
            missing = [n for n in numbers if n not in have[key]]
            if missing:
                out.append(f"{where}: cites {docs[key].relative_to(root).as_posix()} {SECTION}"
                           f"{'-'.join(map(str, numbers[:1] + numbers[1:][-1:]))}, which has no section "
                           f"{', '.join(map(str, missing))}")
    return out


def test_the_checker_finds_broken_citations(tmp_path):
    (tmp_path / "docs").mkdir()
    design = tmp_path / "docs" / "design.md"
    design.write_text("# title\n\n## 1. One\n\n## 2. Two\n### 2.1 not a section heading\n")
    code = tmp_path / "m.py"
    s = SECTION
    code.write_text(f'"""ok (docs/design.md {s}2), ok (design {s}1-2), bad (design {s}3)."""\n'
                    f"# bad range (design.md {s}2-4); bad item (design item 9); reference.md {s}5\n"
                    "x = 1  # the design 2x faster: not a citation\n")
    found = broken([code], {"design": design, "reference": tmp_path / "docs" / "reference.md"}, tmp_path)
    assert found == [
        "m.py:1: cites docs/design.md \u00a73, which has no section 3",
        "m.py:2: cites docs/design.md \u00a72-4, which has no section 3, 4",
        "m.py:2: cites docs/design.md \u00a79, which has no section 9",
        "m.py:2: cites reference but docs/reference.md is not in the repo",
    ]


def test_both_documents_are_in_the_repository_with_numbered_sections():
    for key, path in DOCS.items():
        assert path.is_file(), f"{path.relative_to(ROOT)} is missing: comments cite it"
        assert sections(path), f"{path.relative_to(ROOT)} has no numbered '## N.' headings to cite"


def test_every_citation_resolves():
    files = scanned_files()
    assert any(f.name == "design.md" for f in files) and any(f.suffix == ".py" for f in files)
    found = broken(files, DOCS)
    assert not found, "citations that do not resolve (cite 'docs/design.md \u00a7N' of an existing " \
                      "'## N.' heading):\n" + "\n".join(found)
