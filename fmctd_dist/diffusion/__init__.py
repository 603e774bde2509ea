"""Diffusion Forcing: schedules (pure numpy), model and sampler (torch), training, checkpoints.

Kept import-free so that `fmctd_dist.diffusion.schedule` can be used without torch.
"""
