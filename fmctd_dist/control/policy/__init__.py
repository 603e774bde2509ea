"""The learned low-level goal-conditioned policies that execute plans where no PD law can (the ant, the arm).

Goal-conditioned behaviour cloning with hindsight subgoals, one implementation for every
family: the network (``network``), checkpoints (``checkpoint``), config (``config``),
hindsight pairs (``hindsight``) and the resumable loop (``train``) are shared. A family
brings a spec (``ant``, ``cube``: input layout and features), its dataset rows
(``ant_data``, ``cube_data``), a closed-loop reach test (``ant_reach``, ``cube_reach``) and
the hooks that hand them to the loop (``ant_train``, ``cube_train``; ``hooks``, ``specs``).
The SAC expert that makes the ant's datasets is a data tool and stays in :mod:`fmctd_dist.families.maze.expert`.
"""
