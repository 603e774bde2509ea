"""Tree search for MCTD / P-MCTD / S-MCTD / Fast-MCTD (pure numpy: no torch, no ray).

tree (struct of arrays) -> select (UCT + virtual visits, redundancy-aware claims, max
backup) -> value (the reach reward; a family's own rule, e.g. the cube's, plugged in through value_rule) ->
loop (one search loop for every variant). actions: the child slots as data.
"""

from fmctd_dist.search.actions import ALL, Actions, object_actions, scale_actions
from fmctd_dist.search.loop import IterStats, SearchParams, SearchResult, search
from fmctd_dist.search.select import backup, select_batch
from fmctd_dist.search.tree import EMPTY, ROOT, Tree, empty_tree
from fmctd_dist.search.value import ACHIEVED, NOT_REACHED, WARP, barely_moves, plan_values
from fmctd_dist.search.value_rule import MazeValue, PlanValue

__all__ = [
    "ACHIEVED", "ALL", "EMPTY", "NOT_REACHED", "ROOT", "WARP", "Actions", "IterStats", "MazeValue",
    "PlanValue", "SearchParams", "SearchResult", "Tree", "backup", "barely_moves", "empty_tree", "object_actions",
    "plan_values", "scale_actions", "search", "select_batch",
]
