"""What a ``device`` run would send, and how to send less: the shipped checkpoints stay behind.

    python3 jobs/gpu/device_tree.py size              # bytes that travel (tracked + untracked-not-ignored) vs 64 MiB
    python3 jobs/gpu/device_tree.py slim              # leave checkpoints/ behind: untrack it in the index, ignore it
    python3 jobs/gpu/device_tree.py restore           # undo slim (index and .git/info/exclude); the files never move

Why: the device tool sends the working tree (tracked files and untracked ones git does not
ignore) and refuses more than 64 MiB. Our code and docs are ~2 MB, but the shipped checkpoints
(~5 MB per 6 x 128 model, 25+ of them) are over 120 MB, so a session lent a GPU could not run
``jobs/gpu/gpu_train.py`` or ``jobs/gpu/gpu_check.py`` at all. ``slim`` drops ``checkpoints/`` from the
index (``git rm -r --cached``: no file is deleted, nothing is committed) and lists it in
``.git/info/exclude``, so it neither counts as tracked nor as untracked-not-ignored; a checkpoint
the command needs (gpu_check's ``checkpoints/pointmaze-giant-h5``) then travels through the
tool's ``carry``. ``restore`` puts the index back from HEAD. Never commit while slim (the commit
would delete the checkpoints from the repo); ``status`` in ``size`` says which state you are in.
Standard library only; the size counts what git lists, as the tool does (measured rule of the
device README, not its code: check ``size`` before a run).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
LIMIT = 64 * 2**20  # the device tool's working-tree limit
LEFT_BEHIND = "checkpoints"
# two lines in .git/info/exclude (gitignore has no trailing comments): ours, and the pattern
MARK = f"# jobs/gpu/device_tree.py slim (undo: python3 jobs/gpu/device_tree.py restore)\n/{LEFT_BEHIND}/"


def git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", *args], cwd=repo, check=True, capture_output=True, text=True).stdout


def travelling(repo: Path) -> list[Path]:
    """Paths the device tool sends: tracked (the index) + untracked files git does not ignore."""
    names = git(repo, "ls-files", "-z", "--cached", "--others", "--exclude-standard").split("\0")
    return [repo / n for n in sorted(set(names)) if n and (repo / n).is_file()]


def size_report(repo: Path) -> tuple[int, list[str]]:
    """Total bytes that travel, and lines: the total against the limit and the largest top-level folders."""
    per_top: dict[str, int] = {}
    for p in travelling(repo):
        top = p.relative_to(repo).parts[0]
        per_top[top] = per_top.get(top, 0) + p.stat().st_size
    total = sum(per_top.values())
    state = "slim (checkpoints/ left behind)" if is_slim(repo) else "full"
    lines = [f"travels: {total / 2**20:.1f} MiB of {LIMIT / 2**20:.0f} MiB allowed ({state}): "
             + ("fits" if total <= LIMIT
                else f"too big; `python3 jobs/gpu/device_tree.py slim` leaves {LEFT_BEHIND}/ behind")]
    lines += [f"  {b / 2**20:8.1f} MiB  {top}" for top, b in sorted(per_top.items(), key=lambda kv: -kv[1])[:8]]
    return total, lines


def exclude_file(repo: Path) -> Path:
    return repo / git(repo, "rev-parse", "--git-dir").strip() / "info" / "exclude"


def is_slim(repo: Path) -> bool:
    f = exclude_file(repo)
    return f.is_file() and MARK in f.read_text()


def slim(repo: Path) -> None:
    if is_slim(repo):
        return
    if git(repo, "status", "--porcelain", "--", LEFT_BEHIND).strip():
        raise SystemExit(f"device_tree slim: {LEFT_BEHIND}/ has uncommitted changes; commit or stash them first, "
                         "since restore puts the index back from HEAD")
    f = exclude_file(repo)
    f.parent.mkdir(parents=True, exist_ok=True)
    text = f.read_text() if f.is_file() else ""
    f.write_text(text + ("" if text.endswith("\n") or not text else "\n") + MARK + "\n")
    git(repo, "rm", "-r", "-q", "--cached", "--ignore-unmatch", "--", LEFT_BEHIND)


def restore(repo: Path) -> None:
    git(repo, "reset", "-q", "HEAD", "--", LEFT_BEHIND)
    f = exclude_file(repo)
    if f.is_file():
        f.write_text(f.read_text().replace(MARK + "\n", ""))


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("action", choices=("size", "slim", "restore"))
    ap.add_argument("--repo", type=Path, default=REPO)
    args = ap.parse_args(argv)
    if args.action == "slim":
        slim(args.repo)
    elif args.action == "restore":
        restore(args.repo)
    total, lines = size_report(args.repo)
    print("\n".join(lines))
    if args.action == "slim" and total > LIMIT:
        raise SystemExit("device_tree slim: still over the limit without checkpoints/; see the folders above")


if __name__ == "__main__":
    main(sys.argv[1:])
