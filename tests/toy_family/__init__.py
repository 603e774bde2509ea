"""A toy env family that plugs in as docs/adding-a-family.md says: its package, one registry record, its configs.

A point on an open plane walks toward a goal; the data are straight noisy walks. It exists to prove
that a family needs nothing of the core but the protocol (tests/test_toy_family.py).
"""
