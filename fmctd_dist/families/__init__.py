"""The env families, one package each: maze (point and ant robots), cube (robot arm), visual (images).

Each package holds everything of its family: env, data, episode, action set and value, low-level
control, figures. The core below (search, denoiser, diffusion, planners, evaluation) names none of
them; :mod:`fmctd_dist.registry` maps env names to families.
"""
