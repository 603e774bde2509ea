"""Low-level control shared by the families: the learned goal-conditioned policy (``policy/``).

The families' own controllers live in their packages (the maze's PD follower and ant subgoal
controller in :mod:`fmctd_dist.families.maze`, the arm's scripts in :mod:`fmctd_dist.families.cube`).
"""
