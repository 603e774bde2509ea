"""The search tree as a struct of dense numpy arrays (mctx style).

Every node field is one preallocated array indexed by node id, so selection and backup
are plain index arithmetic, a whole tree can be compared against a golden file, and a
tree never holds references to model tensors. Node ids are handed out per batch in
(parent, slot) order, never in completion order, so a search is reproducible however
the denoising jobs were scheduled.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

ROOT = 0  # node id of the root (the start state; holds no denoised payload)
EMPTY = -1  # children[n, a] of a slot that has not been expanded yet
NO_STATUS = -1  # status of the root and of unused rows (value.py statuses are >= 0)


@dataclass
class Tree:
    """Search tree with capacity N nodes, A children per node (one per action, search.actions).

    Mutated in place by select.py (virtual, claimed), by :func:`add_nodes` and by backup.
    """

    parent: np.ndarray  # [N] int32, parent node id (EMPTY for the root)
    slot: np.ndarray  # [N] int32, child index under the parent = action index (EMPTY for the root)
    depth: np.ndarray  # [N] int32, tree depth (root 0); depth d ran pyramid segment d
    children: np.ndarray  # [N, A] int32, child node id per slot or EMPTY
    visits: np.ndarray  # [N] int32, backups that walked through the node (new leaves: 0)
    virtual: np.ndarray  # [N] float64, virtual visits added during the current batch
    value: np.ndarray  # [N] float64, max over the subtree's simulated values
    claimed: np.ndarray  # [N, A] bool, slot claimed by a selection in the current batch
    status: np.ndarray  # [N] int8, value.py status of the node's simulated plan (NO_STATUS for root)
    born: np.ndarray  # [N] int32, iteration (0-based) that created the node (-1 for the root)
    attempts: np.ndarray  # [N] int32, bad-plan attempt index that produced the payload
    x: np.ndarray  # [N, T, D] float32, tokens at the end of the node's expansion segment (normalised)
    sim_plan: np.ndarray  # [N, F, d] float32, simulated plan of the node in world units
    terminal_depth: int  # nodes at this depth are fully denoised and have no children
    num_nodes: int = 1  # rows [0, num_nodes) are in use

    @property
    def capacity(self) -> int:
        return int(self.parent.shape[0])

    @property
    def num_actions(self) -> int:
        return int(self.children.shape[1])

    def to_json(self) -> dict[str, Any]:
        """Plain-list view of the used rows (payloads left out), floats rounded to 6 decimals."""
        n = self.num_nodes
        out: dict[str, Any] = {"num_nodes": n, "terminal_depth": int(self.terminal_depth)}
        for name in ("parent", "slot", "depth", "children", "visits", "virtual", "value", "status", "born", "attempts"):
            a = getattr(self, name)[:n]
            out[name] = [round(float(v), 6) for v in a] if name in ("virtual", "value") else a.astype(np.int64).tolist()
        return out


def empty_tree(capacity: int, num_actions: int, tokens: int, token_dim: int, plan_frames: int,
               terminal_depth: int, pos_dim: int = 2) -> Tree:
    """A tree holding only the root. ``capacity`` >= 1 + budget + K bounds the node count."""
    n, a = capacity, num_actions
    return Tree(parent=np.full(n, EMPTY, np.int32), slot=np.full(n, EMPTY, np.int32), depth=np.zeros(n, np.int32),
                children=np.full((n, a), EMPTY, np.int32), visits=np.zeros(n, np.int32),
                virtual=np.zeros(n, np.float64), value=np.zeros(n, np.float64), claimed=np.zeros((n, a), bool),
                status=np.full(n, NO_STATUS, np.int8), born=np.full(n, -1, np.int32),
                attempts=np.zeros(n, np.int32), x=np.zeros((n, tokens, token_dim), np.float32),
                sim_plan=np.zeros((n, plan_frames, pos_dim), np.float32), terminal_depth=int(terminal_depth),
                num_nodes=1)


@dataclass(frozen=True)
class Assignment:
    """Deterministic ids for one batch of selected jobs.

    jobs are reordered by (parent, slot, selection order); duplicates of one (parent, slot)
    (redundancy-aware off) share a node id and are told apart by ``copy``.
    """

    order: np.ndarray  # [J] int64, selection index of each job in job order
    parent: np.ndarray  # [J] int32, parent per job (job order)
    slot: np.ndarray  # [J] int32, slot per job (job order)
    node: np.ndarray  # [J] int32, node id the job will fill
    copy: np.ndarray  # [J] int32, 0 for the first job of a (parent, slot), 1, 2, ... for duplicates
    new_nodes: np.ndarray  # [U] int32, distinct new node ids, ascending

    @property
    def size(self) -> int:
        return int(self.node.shape[0])


def assign_ids(tree: Tree, parents: np.ndarray, slots: np.ndarray) -> Assignment:
    """Sort a batch's candidates by (parent, slot) and give each distinct pair the next id."""
    parents = np.asarray(parents, np.int64)
    slots = np.asarray(slots, np.int64)
    order = np.lexsort((np.arange(parents.shape[0]), slots, parents))  # primary key: parent
    p, s = parents[order], slots[order]
    first = np.ones(p.shape[0], bool)
    first[1:] = (p[1:] != p[:-1]) | (s[1:] != s[:-1])
    rank = np.cumsum(first) - 1  # distinct-pair index per job
    node = tree.num_nodes + rank
    start_of_group = np.maximum.accumulate(np.where(first, np.arange(p.shape[0]), 0))
    copy = np.arange(p.shape[0]) - start_of_group
    if node.size and node.max() >= tree.capacity:
        raise ValueError(f"tree capacity {tree.capacity} exceeded (need node {int(node.max())})")
    return Assignment(order=order, parent=p.astype(np.int32), slot=s.astype(np.int32), node=node.astype(np.int32),
                      copy=copy.astype(np.int32), new_nodes=np.unique(node).astype(np.int32))


def add_nodes(tree: Tree, assignment: Assignment, x: np.ndarray, value: np.ndarray, status: np.ndarray,
              sim_plan: np.ndarray, attempts: np.ndarray, iteration: int) -> None:
    """Write a batch's results into the tree (per-job arrays in job order).

    x: [J, T, D], value: [J], status: [J], sim_plan: [J, F, d], attempts: [J].
    Duplicate jobs of one node keep the max value; the payload comes from the first job
    reaching that max.
    """
    j = assignment.size
    assert x.shape[0] == j and value.shape == (j,) and sim_plan.shape[0] == j, "per-job arrays must be in job order"
    for node in assignment.new_nodes:
        idx = np.flatnonzero(assignment.node == node)
        best = int(idx[np.argmax(value[idx])])  # argmax: first of the ties
        par, sl = int(assignment.parent[best]), int(assignment.slot[best])
        tree.parent[node] = par
        tree.slot[node] = sl
        tree.depth[node] = tree.depth[par] + 1
        tree.children[par, sl] = node
        tree.value[node] = value[best]
        tree.status[node] = status[best]
        tree.attempts[node] = attempts[best]
        tree.born[node] = iteration
        tree.x[node] = x[best]
        tree.sim_plan[node] = sim_plan[best]
    tree.num_nodes += int(assignment.new_nodes.shape[0])
