"""The package's import graph has no cycle (docs/design.md §2: what families share sits below them).

Every ``import`` / ``from ... import`` of a ``fmctd_dist`` module counts, deferred ones inside
functions too: a cycle hidden behind a deferred import is still a cycle for a reader. A
module importing its own parent package is not an edge (that is how packages load).
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "fmctd_dist"


def import_graph() -> dict[str, set[str]]:
    """module -> the fmctd_dist modules it imports (by AST, nothing is executed)."""
    mods: dict[str, Path] = {}
    for f in PACKAGE.rglob("*.py"):
        name = ".".join(f.relative_to(PACKAGE.parent).with_suffix("").parts)
        mods[name.removesuffix(".__init__")] = f
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for m, f in mods.items():
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            else:
                continue
            graph[m] |= {t for t in targets if t in mods and t != m and not m.startswith(t + ".")}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def test_the_checker_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle_in_the_package():
    found = cycles(import_graph())
    assert not found, f"import cycles (put what both sides share in a module below them): {found}"


CORE = ("search", "denoiser", "diffusion", "planners", "evaluation", "data", "control")  # name no family

# docs/design.md §2: folder ranks, bottom to top; a folder imports only its own rank and lower ones. A family's
# record counts as records; ``families`` alone is the door (fmctd_dist/families/__init__.py), above everything.
RANKS: dict[str, int] = {
    "errors": 0, "records": 1, "tokens": 1, "seeding": 1, "cli_words": 1, "cli": 1, "registry": 2, "config": 3,
    "hints": 4, "device": 4, "family": 4, "artifacts": 4, "resume": 4, "diffusion": 5, "data": 5,
    "denoiser": 6, "search": 6, "control": 6, "planners": 7, "evaluation": 8, "checkpoint_index": 8,
    "families.maze": 9, "families.cube": 10, "families.visual": 10, "families": 11,
}
DOOR = "fmctd_dist.families"
RECORD_DATA = ("record", "paper")  # a family's record and the plain data it holds (the paper's numbers): rank 1


def modules() -> dict[str, Path]:
    return {".".join(f.relative_to(PACKAGE.parent).with_suffix("").parts).removesuffix(".__init__"): f
            for f in PACKAGE.rglob("*.py")}


def dispatch_edges() -> dict[str, set[str]]:
    """module -> the fmctd_dist modules it names in string constants (``importlib.import_module`` dispatch:
    the registry's records, a record's hooks / data / policy modules)."""
    edges: dict[str, set[str]] = {}
    mods = modules()
    for m, f in mods.items():
        names = {n.value.split(":")[0] for n in ast.walk(ast.parse(f.read_text()))
                 if isinstance(n, ast.Constant) and isinstance(n.value, str)}
        edges[m] = {n for n in names if n in mods and n != m}
    return edges


def full_graph() -> dict[str, set[str]]:
    """The import graph plus dispatch: a module calling ``import_module`` reaches the modules it names and,
    unless it is the door or the registry (which imports the records only), every module a record names."""
    graph, named = import_graph(), dispatch_edges()
    by_records = set().union(*(named[m] for m in graph if m.endswith(".record")))
    for m, f in modules().items():
        if "import_module(" in f.read_text():
            graph[m] |= named[m] | (set() if m in (DOOR, "fmctd_dist.registry") else by_records)
    return graph


def folder(module: str) -> str:
    """A module's rank-table folder: fmctd_dist.<folder>..., fmctd_dist.families.<name>..., a record and its paper
    numbers: records."""
    parts = module.split(".")[1:] or ["fmctd_dist"]
    if parts[0] != "families" or len(parts) == 1:
        return parts[0]
    return "records" if parts[-1] in RECORD_DATA else f"families.{parts[1]}"


def rank_violations(graph: dict[str, set[str]]) -> list[str]:
    return sorted(f"{m} ({folder(m)}, {RANKS[folder(m)]}) -> {t} ({folder(t)}, {RANKS[folder(t)]})"
                  for m, ts in graph.items() for t in ts if RANKS[folder(t)] > RANKS[folder(m)])


def folder_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    out: dict[str, set[str]] = {folder(m): set() for m in graph}
    for m, ts in graph.items():
        out[folder(m)] |= {folder(t) for t in ts} - {folder(m)}
    return out


def test_every_folder_has_a_rank():
    assert {folder(m) for m in modules()} - {"fmctd_dist"} <= set(RANKS)


def test_folders_import_only_their_rank_and_below():
    wrong = rank_violations(full_graph())
    assert not wrong, f"imports upward (hand it down from the caller instead): {wrong}"


def test_no_folder_level_cycle():
    assert not cycles(folder_graph(full_graph()))


def test_the_rank_checker_catches_a_planted_violation():
    graph = full_graph()
    graph["fmctd_dist.planners.mctd"].add("fmctd_dist.evaluation.grid")  # a planner looking up the grid
    graph["fmctd_dist.search.loop"].add("fmctd_dist.families.maze.hooks")  # the core naming a family
    assert len(rank_violations(graph)) == 2
    assert cycles(folder_graph(graph))
    assert folder("fmctd_dist.families.cube.record") == "records" and folder(DOOR) == "families"


def test_family_records_are_light():
    # the registry imports every record by name: a record imports nothing of ours but the record types,
    # or a module of plain data that imports nothing of ours (a family's paper numbers)
    graph = import_graph()
    data = {m for m, targets in graph.items() if not targets}
    heavy = {m: sorted(graph[m] - {"fmctd_dist.records"} - data) for m in graph if m.endswith(".record")}
    assert heavy and not any(heavy.values()), heavy


def test_the_core_imports_no_family():
    # docs/design.md §2: nothing below the families names one, statically or by name; only the door looks
    # families up (the registry's import of the records aside)
    wrong = sorted(f"{m} -> {t}" for m, ts in full_graph().items() for t in ts
                   if m.split(".")[1] in CORE and t.startswith("fmctd_dist.families"))
    assert not wrong, wrong


def family_names_in_code(folders: tuple[str, ...] = ("search", "denoiser", "diffusion", "planners", "evaluation")) \
        -> list[str]:
    """Every token of the core's code (not a comment, not a docstring) that names one of our families."""
    import io
    import re
    import tokenize

    out = []
    for d in folders:
        for f in sorted((PACKAGE / d).rglob("*.py")):
            src = f.read_text()
            docs = set()
            for n in ast.walk(ast.parse(src)):
                body = getattr(n, "body", None)
                if isinstance(n, (ast.Module, ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and body \
                        and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                    docs |= set(range(body[0].lineno, body[0].end_lineno + 1))
            for t in tokenize.generate_tokens(io.StringIO(src).readline):
                if t.type != tokenize.COMMENT and t.start[0] not in docs and re.search("cube|visual|antmaze", t.string):
                    out.append(f"{f.relative_to(PACKAGE)}:{t.start[0]}: {t.string[:60]}")
    return out


def test_the_core_names_no_family():
    # issue 53: search, denoiser, diffusion, planners and evaluation name a family in comments and docstrings only
    assert not family_names_in_code(), family_names_in_code()
