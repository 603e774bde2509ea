"""key=value command-line words shared by the job scripts (standard library only: jobs/gpu/gpu_train.py
imports it before the project is installed)."""

from __future__ import annotations


def merge(*word_lists: list[str]) -> list[str]:
    """key=value words, a later list's value replacing an earlier one's for the same key (the CLI
    refuses a key given twice)."""
    out: dict[str, str] = {}
    for words in word_lists:
        for w in words:
            out[w.split("=", 1)[0]] = w
    return list(out.values())
