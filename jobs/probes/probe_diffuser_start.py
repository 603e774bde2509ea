"""How much does a Diffuser checkpoint use its inpainted start? (issue 7; docs/results.md section 3.1)

    python jobs/probes/probe_diffuser_start.py checkpoints/pointmaze-medium-diffuser [key=value ...]

Feeds 16 validation windows noised to timestep k (plan frames noisy, start clean, exactly as in
training) and prints, in world units: the x0 error at plan frame 1, frame 2, mid-plan and the last
frame, and how far the frame-1 prediction moves when the start is swapped for another window's.
A model that uses the start has a small frame-1 error and moves frame 1 with the start. Then plans
one guided plan per task and noise seed 0-2 and prints its first step and largest later step.
"""
import sys

from fmctd_dist.cli import print_usage, wants_help

if len(sys.argv) < 2 or wants_help(sys.argv[1:]):
    print_usage()
    sys.exit(0 if len(sys.argv) >= 2 else 2)
import numpy as np, torch  # noqa: E401,E402
from fmctd_dist.config import load_config
from fmctd_dist.diffusion.checkpoint import load_checkpoint
from fmctd_dist.families.maze.data import load_dataset
from fmctd_dist.data.windows import train_data
from fmctd_dist.diffusion.train import DiffuserLoss
torch.set_num_threads(1)
ck = sys.argv[1]
cfg = load_config(["method=diffuser", "env=pointmaze-medium", f"checkpoint={ck}"] + sys.argv[2:])
model, manifest = load_checkpoint(cfg.checkpoint_dir(), cfg); model.eval()
td = train_data(cfg, load_dataset(cfg))
x0 = torch.as_tensor(td.val_batches(1, 16)[0])
L = DiffuserLoss(cfg, torch.device("cpu"))
std = td.normaliser.std
g = torch.Generator().manual_seed(0)
with torch.no_grad():
  for k in [1, 50, 99]:
    b, t, _ = x0.shape
    kk = torch.full((b, t), k); kk[:, 0] = L.t_start
    noise = torch.randn(x0.shape, generator=g)
    xt = L.sqrt_ab[kk][..., None] * x0 + L.sqrt_1m_ab[kk][..., None] * noise
    xt[:, 0] = L.sqrt_ab[L.t_start] * x0[:, 0]
    pred = model(xt, kk)
    err = ((pred - x0).numpy() * std).__pow__(2).sum(-1) ** 0.5  # world units [B, T]
    # shifted start: replace start by another sample's start
    xs = xt.clone(); xs[:, 0] = xt.roll(1, 0)[:, 0]
    ps = model(xs, kk)
    mv = ((ps - pred)[:, 1].numpy() * std); dstart = ((x0.roll(1,0)[:,0]-x0[:,0]).numpy()*std)
    print(f"k {k:3d}: err frame1 {err[:,1].mean():.2f} frame2 {err[:,2].mean():.2f} mid {err[:,250].mean():.2f} "
          f"last {err[:,-1].mean():.2f}; "
          f"start moved {np.linalg.norm(dstart,axis=1).mean():.2f} -> "
          f"frame1 moved {np.linalg.norm(mv,axis=1).mean():.2f}")

# What that does to plans: the first step of a guided plan (start -> plan frame 1) and the largest
# step after it, per task, for noise seeds 0-2 (the warp threshold is 1.0).
from fmctd_dist.denoiser.local import LocalDenoiser  # noqa: E402
from fmctd_dist.diffusion.checkpoint import normaliser_from_manifest  # noqa: E402
from fmctd_dist.families import plan_rules  # noqa: E402
from fmctd_dist.families.maze.make import make_env  # noqa: E402
from fmctd_dist.planners import make_planner  # noqa: E402

env = make_env(cfg.env.name)
planner = make_planner(cfg, LocalDenoiser(model, cfg.diffusion, "cpu", 1), normaliser_from_manifest(manifest),
                       plan_rules(cfg))
for task in range(1, 6):
    reset = env.reset(task, 0)
    cells = []
    for seed in range(3):
        path = np.concatenate([reset.obs[None], planner.plan(reset.obs, reset.goal, seed=seed).waypoints])
        steps = np.linalg.norm(np.diff(path, axis=0), axis=1)
        cells.append(f"{steps[0]:.2f} / {steps[1:].max():.2f}")
    print(f"task {task} (guidance {cfg.method.guidance_scale}): first step / largest later step, seeds 0-2: "
          + ", ".join(cells))
