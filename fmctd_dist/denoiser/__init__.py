"""Denoiser protocol and its implementations (in-process and Ray actor pool)."""
