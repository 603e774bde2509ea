"""Tree search for MCTD / P-MCTD / S-MCTD / Fast-MCTD (pure numpy: no torch, no ray).

tree (struct of arrays) -> select (UCT + virtual visits, redundancy-aware claims, max
backup) -> value (maze reward) -> loop (one search loop for every variant).
"""

from fmctd_dist.search.loop import IterStats, SearchParams, SearchResult, search
from fmctd_dist.search.select import backup, select_batch
from fmctd_dist.search.tree import EMPTY, ROOT, Tree, empty_tree
from fmctd_dist.search.value import ACHIEVED, NOT_REACHED, WARP, barely_moves, plan_values

__all__ = [
    "ACHIEVED", "EMPTY", "NOT_REACHED", "ROOT", "WARP", "IterStats", "SearchParams", "SearchResult", "Tree",
    "backup", "barely_moves", "empty_tree", "plan_values", "search", "select_batch",
]
