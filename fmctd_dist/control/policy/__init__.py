"""The learned low-level goal-conditioned policy that executes plans where no PD law can (the ant).

Goal-conditioned behaviour cloning with hindsight subgoals: the network and its checkpoints
(``ant``), its config (``config``), the dataset rows and hindsight subgoals (``ant_data``),
the resumable training loop (``train``) and the closed-loop reach rate (``ant_reach``).
The SAC expert that makes the ant's datasets is a data tool and stays in :mod:`fmctd_dist.ant`.
"""
