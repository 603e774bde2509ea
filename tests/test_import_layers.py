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


def dispatch_edges() -> dict[str, set[str]]:
    """module -> the fmctd_dist modules it names in string constants (``importlib.import_module`` dispatch:
    the registry's records, a record's hooks / data / policy modules), for modules that import importlib."""
    mods = {".".join(f.relative_to(PACKAGE.parent).with_suffix("").parts).removesuffix(".__init__"): f
            for f in PACKAGE.rglob("*.py")}
    edges: dict[str, set[str]] = {}
    for m, f in mods.items():
        tree = ast.parse(f.read_text())
        names = {n.value.split(":")[0] for n in ast.walk(tree)
                 if isinstance(n, ast.Constant) and isinstance(n.value, str)}
        edges[m] = {n for n in names if n in mods and n != m}
    return edges


def test_family_records_are_light():
    # the registry imports every record by name: a record imports nothing of ours but the record types,
    # or a module of plain data that imports nothing of ours (a family's paper numbers)
    graph = import_graph()
    data = {m for m, targets in graph.items() if not targets}
    heavy = {m: sorted(graph[m] - {"fmctd_dist.records"} - data) for m in graph if m.endswith(".record")}
    assert heavy and not any(heavy.values()), heavy


def test_the_core_imports_no_family():
    # docs/design.md §2: the core asks the registry and the family protocol; a family's package is never imported
    # from below, statically or by name (the registry's own dispatch to the records is the one door)
    graph = import_graph()
    for m, targets in dispatch_edges().items():
        graph[m] |= targets
    wrong = sorted(f"{m} -> {t}" for m, ts in graph.items() for t in ts
                   if m.split(".")[1] in CORE and t.startswith("fmctd_dist.families."))
    assert not wrong, wrong
