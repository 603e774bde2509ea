"""Ant locomotion expert for AntMaze data: a SAC policy that walks the OGBench ant in a commanded direction.

OGBench's AntMaze datasets were made by such an expert, whose weights cannot be fetched
here, so we train our own: ``direction_env`` (task), ``sac`` (algorithm), ``train``
(resumable loop), ``evaluate`` (direction-following success), ``expert`` (checkpoints).
"""
