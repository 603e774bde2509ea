"""Training loop of the goal-conditioned policy (ant, cube): resumable, bitwise deterministic from a seed.

Each step draws ``batch_size`` (row, hindsight subgoal) pairs from the train split and
takes one AdamW step on the MSE to the row's action. Every ``val_every`` steps the MSE on a
fixed set of ``val_rows`` val pairs is logged, beside the family's noise floor where it has
one (the ant: the expert's MSE on the same rows; the data is expert + N(0, 0.2^2)).
Every ``ckpt_every`` steps it writes model.pt + manifest.json and train_state.pt (network,
optimiser, batch RNG, history); rerunning continues from there and is bitwise the
uninterrupted run (same thread count). ``policy.time_budget_s`` stops a run early at a
checkpoint (the next call continues it). At the end, with ``reach.rows > 0``, the reach
rates of the policy and the family's references go into the manifest. What differs by
family (spec, rows, floor, reach test) comes from the hooks its caller hands in
(:func:`fmctd_dist.families.policy_hooks`).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from fmctd_dist.config import Config, git_sha
from fmctd_dist.artifacts import MANIFEST_FILE
from fmctd_dist.control.policy.checkpoint import read_policy_manifest, save_policy
from fmctd_dist.control.policy.config import PolicyConfig, policy_dir
from fmctd_dist.control.policy.hindsight import sample_pairs
from fmctd_dist.control.policy.network import GoalPolicyNet, build_net
from fmctd_dist.device import set_threads
from fmctd_dist.errors import CheckpointError
from fmctd_dist.resume import TrainRun, check_resume, load_part_states, load_train_state, part_states, \
    save_train_state, stream_rng
BATCH_STREAM, VAL_STREAM, NORM_STREAM = 3, 4, 5  # SeedSequence([policy.seed, stream])
NORM_ROWS = 65_536  # hindsight pairs whose inputs set the network's input normalisation
RESUME_FIELDS = ("policy.seed", "policy.hidden", "policy.geom_p", "policy.geom_draws", "policy.max_subgoal_dist",
                 "policy.drop_fallen", "policy.batch_size")


def make_batch(rows: Any, i: np.ndarray, j: np.ndarray, max_dist: float) -> tuple[torch.Tensor, torch.Tensor]:
    """(row, subgoal row) indices -> inputs [B, in_dim], target actions [B, act_dim]."""
    return torch.from_numpy(rows.inputs(i, j, max_dist)), torch.from_numpy(rows.actions[i])


def pairs(rows: Any, rng: np.random.Generator, n: int, pcfg: PolicyConfig) -> tuple[np.ndarray, np.ndarray]:
    return sample_pairs(rows.valid, rows.end, rng, n, pcfg.policy.geom_p, pcfg.policy.geom_draws)


@torch.no_grad()
def mse(net: GoalPolicyNet, x: torch.Tensor, y: torch.Tensor, chunk: int = 4096) -> float:
    net.eval()
    total = sum(float((net(x[k:k + chunk]) - y[k:k + chunk]).square().sum()) for k in range(0, len(x), chunk))
    net.train()
    return total / y.numel()


def _finished(m: dict[str, Any], out: Path) -> dict[str, Any]:
    """Summary of a finished run from its manifest ``m`` (reach included)."""
    return {"step": int(m["steps"]), "wall_time_s": float(m["wall_time_s"]), "out_dir": str(out),
            "resumed_from": int(m["steps"]), "name": m["name"], "rows": m["dataset"]["rows"], "stopped": None,
            **m["metrics"]}


def train_policy(cfg: Config, pcfg: PolicyConfig, hooks: Any, out_dir: str | Path | None = None,
                 progress: bool = True) -> dict[str, Any]:
    """Train (or resume) into out_dir (default policy.out) with the env's policy ``hooks``; returns the manifest's
    summary."""
    p = pcfg.policy
    set_threads(p.threads)
    spec = hooks.spec
    out = Path(out_dir) if out_dir is not None else policy_dir(cfg, pcfg)
    train_rows, val_rows, data_manifest = hooks.load(cfg, pcfg)
    data_sha = dict(data_manifest["sha256"])

    m = read_policy_manifest(out, spec) if (out / MANIFEST_FILE).exists() else None  # another kind: CheckpointError
    state = load_train_state(out)
    if state is None and m is not None:
        if int(m["steps"]) < p.max_steps:
            raise CheckpointError(f"{out} holds a policy ({m['steps']} steps) without train_state.pt, so its "
                                  "optimiser is gone; train into a fresh policy.out dir (this one is left as it is)")
        return _finished(m, out)  # finished (e.g. shipped): nothing to do
    if state is not None:
        check_resume(out, "policy", "policy.out", {**state["config"], "env": state["env"]},
                     {**pcfg.to_dict(), "env": cfg.env.name}, RESUME_FIELDS + ("env",),
                     [(f"{split} sha256", state["dataset_sha256"].get(split), sha) for split, sha in data_sha.items()],
                     data_fix="point data.* at the dataset it started on")
        if int(state["step"]) >= p.max_steps:
            return _finished(read_policy_manifest(out, spec), out)

    net = build_net(p.hidden, spec.in_dim, spec.act_dim, p.seed)
    ni, nj = pairs(train_rows, stream_rng(p.seed, NORM_STREAM), NORM_ROWS, pcfg)
    net.set_normaliser(make_batch(train_rows, ni, nj, p.max_subgoal_dist)[0].numpy())
    opt = torch.optim.AdamW(net.parameters(), lr=p.lr, weight_decay=p.weight_decay)
    rng = stream_rng(p.seed, BATCH_STREAM)
    vi, vj = pairs(val_rows, stream_rng(p.seed, VAL_STREAM), p.val_rows, pcfg)
    vx, vy = make_batch(val_rows, vi, vj, p.max_subgoal_dist)
    floor = hooks.floor(cfg, val_rows, vi)
    reach: dict[str, Any] | None = None
    if state is not None:
        load_part_states(state, net=net, opt=opt, rng=rng)
        for group in opt.param_groups:  # policy.lr may change between runs
            group["lr"] = p.lr
    run = TrainRun(f"policy {cfg.env.name}", p.max_steps, state or {"history": {"train": [], "val": []}},
                   progress=progress)  # history: [step, loss]
    hist, resumed_from = run.history, None if state is None else run.step

    dataset = {**hooks.dataset_fields(cfg, data_manifest), "sha256": data_sha, "digest": data_sha["train"][:16],
               "episodes": data_manifest["episodes"], "episode_steps": data_manifest["episode_steps"],
               "seed": data_manifest["seed"], "noise": data_manifest["noise"],
               "rows": {"train": train_rows.stats, "val": val_rows.stats}}

    def metrics() -> dict[str, Any]:
        best = min(hist["val"], key=lambda sv: sv[1]) if hist["val"] else [None, None]
        return {"train_loss": hist["train"][-1][1] if hist["train"] else None,
                "val_loss": hist["val"][-1][1] if hist["val"] else None, "val_mse_expert": floor,
                "best_val_loss": best[1], "best_val_step": best[0],  # far below `steps`: overfitting
                "reach": reach}

    def save() -> None:
        save_policy(out, net, spec, {
            "config": pcfg.to_dict(), "env": cfg.env.name, "dataset": dataset, "git_sha": git_sha(),
            "steps": run.step, "wall_time_s": run.clock.wall_s, "metrics": metrics(), "val_history": hist["val"],
            "data_config": {k: getattr(cfg.data, k) for k in ("root", "seed", "episodes", "episode_steps", "noise",
                                                              "expert")},
        })
        save_train_state(out, {**part_states(net=net, opt=opt, rng=rng), **run.state(), "config": pcfg.to_dict(),
                               "env": cfg.env.name, "dataset_sha256": data_sha})

    stopped = None
    net.train()
    while not run.last:
        i, j = pairs(train_rows, rng, p.batch_size, pcfg)
        x, y = make_batch(train_rows, i, j, p.max_subgoal_dist)
        loss = (net(x) - y).square().mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        run.tick(float(loss.detach()))
        if run.due(p.log_every):
            run.log()
        if run.due(p.val_every):
            hist["val"].append([run.step, mse(net, vx, vy)])
        if run.last and pcfg.reach.rows > 0:
            reach = run_reach(cfg, pcfg, hooks, net, val_rows)
        saved = run.checkpoint(p.ckpt_every, save)
        if saved and not run.last and 0 < p.time_budget_s <= time.perf_counter() - run.clock.started:  # per call
            stopped = f"policy.time_budget_s={p.time_budget_s:g} reached at step {run.step}; rerun to continue"
            break
    run.close()
    return {"step": run.step, "wall_time_s": run.clock.wall_s, "out_dir": str(out), "resumed_from": resumed_from,
            "name": spec.name, "rows": dataset["rows"], "stopped": stopped, **metrics()}


def run_reach(cfg: Config, pcfg: PolicyConfig, hooks: Any, net: GoalPolicyNet, val_rows: Any) -> dict[str, Any]:
    """Reach rate of this network (and of the family's references when asked) on val rows."""
    max_dist, make_input = pcfg.policy.max_subgoal_dist, hooks.spec.make_input

    @torch.no_grad()
    def policy(obs: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        return net(torch.from_numpy(make_input(obs, subgoal, max_dist))).numpy().astype(np.float64)

    net.eval()
    out = hooks.reach(cfg, pcfg, policy, val_rows)
    net.train()
    return out
