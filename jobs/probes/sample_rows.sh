#!/usr/bin/env bash
# A sample of each family's grid (2 episodes per family and method kind), for the before/after row
# comparison of a refactor (issue 53 item 5):
#   bash jobs/probes/sample_rows.sh <worktree of a commit> <out>   (then jobs/probes/compare_rows.py)
set -u
if [[ "${1:-}" == -h || "${1:-}" == --help || $# -lt 2 ]]; then sed -n '2,4p' "$0" | sed 's/^# \{0,1\}//'; exit 0; fi
cd "$1"; out=$2
export PYTHONPATH="$1" OMP_NUM_THREADS=1 MUJOCO_GL=egl
e() { python jobs/eval.py runner=local eval.threads=1 eval.out="$out" eval.run=sample 'tasks=[1]' "$@" 2>&1 | tail -3; }
e method=fast-mctd env=pointmaze-medium 'seeds=[0,1]'
e method=mctd env=pointmaze-medium 'seeds=[0,1]' method.budget=40
e method=diffusion-forcing env=pointmaze-medium 'seeds=[0,1]'
e method=fast-mctd env=antmaze-medium 'seeds=[0,1]'
e method=fast-mctd-replan env=cube-single 'seeds=[0,1]'
e method=diffuser-replan env=cube-single 'seeds=[0,1]'
e method=fast-mctd env=visual-pointmaze-medium env.warp_sparse=8.0 'seeds=[0,1]'
echo SAMPLE DONE
