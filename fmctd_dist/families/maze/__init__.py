"""The maze family: PointMaze and AntMaze over OGBench (env_only: no network), one package for both robots.

Env: ``geometry`` (maze, BFS, the OGBench env) -> ``tasks`` (start/goal protocol) -> ``pointmaze``,
``antmaze`` -> ``make``. Data: ``oracle``, ``navigate`` -> ``point_data``, ``ant_data`` (the ant
``expert``, a SAC walker) -> ``data``. Control: ``pd`` (point), ``subgoal`` + ``ant_controller`` + the
learned ``ant_policy`` (ant), ``robots`` (which one a maze uses). Planning and episodes: ``hooks``,
``episode``; measures: ``plan_quality`` (the denoiser-quality table of jobs/bench_denoiser.py).
"""
