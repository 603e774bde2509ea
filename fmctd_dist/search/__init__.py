"""Tree search for MCTD / P-MCTD / S-MCTD / Fast-MCTD (pure numpy: no torch, no ray).

tree (struct of arrays) -> select (UCT + virtual visits, redundancy-aware claims, max
backup) -> value (the reach reward; a family's own rule, e.g. the cube's, plugged in through value_rule) ->
loop (one search loop for every variant). actions: the child slots as data.
"""
