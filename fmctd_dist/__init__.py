"""fmctd_dist: Ray-distributed Fast Monte Carlo Tree Diffusion.

Subpackages follow the data flow: envs -> data -> diffusion -> search -> denoiser ->
planners -> evaluation. ``search`` is pure numpy; torch lives in ``diffusion`` and
``denoiser.local``; Ray only in ``denoiser.ray_pool`` and ``evaluation.ray_runner``.
"""

__version__ = "0.1.0"
