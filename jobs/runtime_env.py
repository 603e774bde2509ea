"""The Ray runtime environment for submitting the eval job with the same key=value words: JSON on stdout.

    ray job submit --working-dir . --runtime-env-json "$(python jobs/runtime_env.py tasks=[1] seeds=[0])" \
      -- python jobs/eval.py tasks=[1] seeds=[0]
    python jobs/runtime_env.py env=antmaze-large method=mctd --size     # also: what the upload weighs

The upload then holds the code, the configs and only the checkpoints that job reads (found by running
the job's own checks), well under Ray's 100 MiB limit however many models the repository ships. The
checks run here, so a config whose inputs are broken fails before anything is uploaded.
"""

import json
import sys

from fmctd_dist.cli import run
from fmctd_dist.config import REPO_ROOT, load_config
from fmctd_dist.evaluation.job_upload import runtime_env, upload_bytes
from fmctd_dist.families import hooks_for


def main(argv: list[str]) -> int:
    size = "--size" in argv
    cfg = load_config([a for a in argv if a != "--size"])
    env = runtime_env(cfg, hooks_for)
    print(json.dumps(env))
    if size:
        print(f"upload: {upload_bytes(REPO_ROOT, env) / 2**20:.1f} MiB (Ray's limit: 100 MiB)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    run(main)
