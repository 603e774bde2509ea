"""Selection (UCT with virtual visits, redundancy-aware claims) and max backup.

P-MCTD runs K descents per iteration without updating values in between (delayed
update). Virtual visits make later descents of the same batch avoid paths already taken,
and the per-batch claim mask keeps two descents from expanding the same slot. Only the
virtual counts and claims change during a batch; backup runs once the batch is scored.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from fmctd_dist.search.tree import EMPTY, ROOT, Tree


class Candidates(NamedTuple):
    """Output of one selection batch, in selection order."""

    parents: np.ndarray  # [J] int32, node whose slot was claimed
    slots: np.ndarray  # [J] int32, claimed slot (action index)
    attempts: int  # descents run (<= K)
    wasted: int  # descents that ended with nothing to claim


def uct_scores(tree: Tree, node: int, c: float, w: float) -> np.ndarray:
    """[A] float64 UCT score per slot of ``node`` (-inf for empty slots).

    n_i = visits_i + w * virtual_i, N = sum of n_i over filled siblings,
    score_i = value_i + c * sqrt(max(ln(N + 1e-6), 0) / (n_i + 1e-6)).
    The log is clamped at 0 for N < 1 so the score is defined for any w.
    """
    kids = tree.children[node]
    filled = kids != EMPTY
    ids = np.where(filled, kids, 0)
    n = tree.visits[ids] + w * tree.virtual[ids]
    total = float(np.sum(n[filled]))
    log_term = max(math.log(total + 1e-6), 0.0)
    scores = tree.value[ids] + c * np.sqrt(log_term / (n + 1e-6))
    return np.where(filled, scores, -np.inf)


def uct_select(tree: Tree, node: int, c: float, w: float) -> int:
    """Slot of the child to descend into; ``node`` must have every slot filled.

    Children never visited (n_i == 0) come first, highest value first, ties to the lowest
    slot: with N >= 1 the authors' formula gives them a ~1e3 bonus, so this is the same
    order made well defined for N == 0. Otherwise argmax of :func:`uct_scores`.
    """
    kids = tree.children[node]
    assert np.all(kids != EMPTY), f"node {node} has empty slots; it is not selectable"
    n = tree.visits[kids] + w * tree.virtual[kids]
    fresh = n == 0
    if np.any(fresh):
        vals = np.where(fresh, tree.value[kids], -np.inf)
        return int(np.argmax(vals))
    return int(np.argmax(uct_scores(tree, node, c, w)))


def claimable(tree: Tree, node: int, redundancy_aware: bool) -> np.ndarray:
    """[A] bool: empty slots of ``node`` a descent may claim (none at terminal depth)."""
    if tree.depth[node] >= tree.terminal_depth:
        return np.zeros(tree.num_actions, bool)
    free = tree.children[node] == EMPTY
    return free & ~tree.claimed[node] if redundancy_aware else free


def descend(tree: Tree, rng: np.random.Generator, c: float, w: float, redundancy_aware: bool,
            leaf_parallel: bool) -> tuple[int, int] | None:
    """One descent from the root (docs/reference.md §3 step 1); returns (parent, slot) or None if wasted.

    Walks down while the node has nothing claimable, is not terminal and has every slot
    filled; each chosen child gets +1 virtual visit (+A with leaf parallelisation). The slot
    is drawn at random among the claimable ones, as in the authors' code.
    """
    node = ROOT
    bump = float(tree.num_actions) if leaf_parallel else 1.0
    while True:
        free = claimable(tree, node, redundancy_aware)
        if free.any():
            break
        if tree.depth[node] >= tree.terminal_depth or np.any(tree.children[node] == EMPTY):
            return None  # terminal, or all empty slots already claimed in this batch
        child = int(tree.children[node, uct_select(tree, node, c, w)])
        tree.virtual[child] += bump
        node = child
    options = np.flatnonzero(free)
    slot = int(options[rng.integers(options.shape[0])])
    tree.claimed[node, slot] = True
    return node, slot


def open_slots(tree: Tree) -> int:
    """Number of unclaimed empty slots of non-terminal nodes in the whole tree."""
    n = tree.num_nodes
    live = tree.depth[:n] < tree.terminal_depth
    free = (tree.children[:n] == EMPTY) & ~tree.claimed[:n]
    return int(np.sum(free[live]))


def select_batch(tree: Tree, k: int, rng: np.random.Generator, *, c: float = math.sqrt(2.0), w: float = 1.0,
                 redundancy_aware: bool = True, leaf_parallel: bool = False) -> Candidates:
    """Up to ``k`` descents with delayed update; clears the claim mask first.

    Stops early once no unclaimed empty slot is left anywhere (with redundancy-aware
    claims; without, only when the tree has no empty slot at all).
    """
    tree.claimed[:] = False
    parents: list[int] = []
    slots: list[int] = []
    wasted = attempts = 0
    remaining = open_slots(tree)
    while attempts < k and remaining > 0:
        attempts += 1
        picked = descend(tree, rng, c, w, redundancy_aware, leaf_parallel)
        if picked is None:
            wasted += 1
            continue
        parents.append(picked[0])
        slots.append(picked[1])
        if redundancy_aware:
            remaining -= 1
    return Candidates(np.asarray(parents, np.int32), np.asarray(slots, np.int32), attempts, wasted)


def backup(tree: Tree, parents: np.ndarray) -> None:
    """Max backup once per distinct parent: value = max over children, visits += 1, virtual = 0.

    New leaves keep visits 0. The result does not depend on the order of the parents.
    """
    for start in np.unique(np.asarray(parents)):
        node = int(start)
        while node != EMPTY:
            kids = tree.children[node]
            kids = kids[kids != EMPTY]
            if kids.size:
                tree.value[node] = float(np.max(tree.value[kids]))
            tree.visits[node] += 1
            tree.virtual[node] = 0.0
            node = int(tree.parent[node])
