"""Offline data: oracle, navigate datasets (.npz + manifest), training windows, token codec."""
