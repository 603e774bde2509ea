"""Evaluation: one episode (plan -> PD control), per-episode Parquet rows, tables and plots."""
