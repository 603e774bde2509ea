"""SAC training loop for the ant direction expert, resumable and deterministic from a seed.

One env step, then ``updates_per_step`` SAC updates (after ``start_steps`` uniform random
steps). Every ``ckpt_every`` steps it writes model.pt + manifest.json (the actor: what
dataset generation needs) and train_state.pt (networks, optimisers, every RNG, the env's
MuJoCo state mid-episode, and the newest ``buffer_save`` replay transitions). Rerunning
continues from there; when the saved buffer holds every transition seen, the resumed run
is bitwise the uninterrupted one, otherwise it continues on the newest transitions only.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from fmctd_dist.families.maze.expert.config import AntExpertConfig
from fmctd_dist.config import git_sha
from fmctd_dist.families.maze.expert.direction_env import ACT_DIM, OBS_DIM, AntDirectionEnv
from fmctd_dist.families.maze.expert.evaluate import evaluate_directions, make_eval_env
from fmctd_dist.artifacts import MANIFEST_FILE
from fmctd_dist.families.maze.expert.expert import read_expert_manifest, save_expert
from fmctd_dist.families.maze.expert.sac import SAC, ReplayBuffer
from fmctd_dist.device import set_threads
from fmctd_dist.errors import CheckpointError
from fmctd_dist.resume import TrainRun, check_resume, load_part_states, load_train_state, part_states, \
    save_train_state, stream_rng
RNG_STREAM = 2  # SeedSequence([seed, RNG_STREAM]): random warm-up actions and replay indices
RECENT = 20  # episodes in the progress bar's running means
# Fields a resumed run must share with the saved one (everything else may change between runs).
RESUME_FIELDS = ("expert.seed", "sac.hidden", "env.episode_steps", "env.resample_every", "env.healthy_reward",
                 "env.ctrl_cost", "env.reset_noise")


def train_expert(cfg: AntExpertConfig, out_dir: str | Path | None = None, progress: bool = True) -> dict[str, Any]:
    """Train (or resume) the expert into out_dir (default cfg.out_dir()); returns the manifest's summary."""
    set_threads(cfg.expert.threads)
    out_dir = Path(out_dir) if out_dir is not None else cfg.out_dir()
    ec, seed = cfg.expert, cfg.expert.seed
    env = AntDirectionEnv(cfg.env, seed=seed)
    eval_env = make_eval_env(cfg.env, cfg.eval)
    agent = SAC(OBS_DIM, ACT_DIM, cfg.sac, seed=seed)
    buffer = ReplayBuffer(cfg.sac.buffer_size, OBS_DIM, ACT_DIM)
    rng = stream_rng(seed, RNG_STREAM)
    ep = {"ret": 0.0, "len": 0, "speed": 0.0}

    state = load_train_state(out_dir)
    if state is not None:
        check_resume(out_dir, "ant expert", "expert.out", state["config"], cfg.to_dict(), RESUME_FIELDS)
        load_part_states(state, agent=agent, buffer=buffer, numpy_rng=rng)
        obs, ep = env.set_state(state["env"]), state["episode"]
    elif (out_dir / MANIFEST_FILE).exists():
        manifest = read_expert_manifest(out_dir)
        if int(manifest["env_steps"]) >= ec.max_steps:  # a finished (e.g. shipped) expert: nothing to do
            return {"step": int(manifest["env_steps"]), "wall_time_s": float(manifest["wall_time_s"]),
                    "out_dir": str(out_dir), "resumed_from": int(manifest["env_steps"]),
                    **manifest["metrics"]}
        raise CheckpointError(
            f"{out_dir} holds an expert ({manifest['env_steps']} env steps) without train_state.pt, so its critics, "
            "optimisers and replay buffer are gone; train into a fresh expert.out dir (this one is left as it is)"
        )
    else:
        obs = env.reset()
    run = TrainRun("ant expert", ec.max_steps, state or {"history": {"episodes": [], "eval": [], "updates": []}},
                   progress=progress, names=())  # [step, return, length, speed] / ...
    hist, resumed_from = run.history, None if state is None else run.step

    def evaluate() -> None:
        agent.actor.eval()
        m = evaluate_directions(lambda o: agent.act(o, deterministic=True), cfg.env, cfg.eval, env=eval_env)
        agent.actor.train()
        hist["eval"].append({"step": run.step, **m})

    def save() -> None:
        last_eval = hist["eval"][-1] if hist["eval"] else None
        save_expert(out_dir, agent.actor, {
            "config": cfg.to_dict(), "env_steps": run.step, "updates": agent.updates, "wall_time_s": run.clock.wall_s,
            "git_sha": git_sha(), "seed": seed, "metrics": {"eval": last_eval, **_recent(hist)},
            "eval_history": hist["eval"], "ogbench_env": "ogbench.online_locomotion.ant.AntEnv (open arena)",
        })
        save_train_state(out_dir, {**part_states(agent=agent, numpy_rng=rng), **run.state(),
                                   "buffer": buffer.state_dict(ec.buffer_save), "env": env.get_state(), "episode": ep,
                                   "config": cfg.to_dict()})

    last_update = None
    while not run.last:
        if run.step < ec.start_steps:
            action = rng.uniform(-1.0, 1.0, ACT_DIM)
        else:
            action = agent.act(obs)
        next_obs, reward, terminated, truncated, info = env.step(action)
        buffer.add(obs, action, reward, next_obs, terminated)
        obs = next_obs
        ep["ret"] += reward
        ep["len"] += 1
        ep["speed"] += info["speed"]
        if terminated or truncated:
            hist["episodes"].append([run.step + 1, ep["ret"], ep["len"], ep["speed"] / ep["len"]])
            ep = {"ret": 0.0, "len": 0, "speed": 0.0}
            obs = env.reset()
        run.tick()
        if run.step > ec.start_steps:  # one update per step from the first policy step on
            for _ in range(ec.updates_per_step):
                last_update = agent.update(buffer.sample(rng, cfg.sac.batch_size))
        if run.due(ec.log_every):
            if last_update is not None:
                hist["updates"].append([run.step, last_update["critic_loss"], last_update["q"], last_update["alpha"]])
            run.log(**_shown(hist, last_update))
        if run.due(cfg.eval.every):
            evaluate()
        run.checkpoint(ec.ckpt_every, save)
    run.close()
    env.close()
    eval_env.close()
    return _summary(run.step, run.clock.wall_s, hist, out_dir, resumed_from)


def _recent(hist: dict[str, Any]) -> dict[str, Any]:
    eps = hist["episodes"][-RECENT:]
    if not eps:
        return {"recent_return": None, "recent_length": None, "recent_speed": None}
    a = np.asarray(eps, dtype=np.float64)
    return {"recent_return": float(a[:, 1].mean()), "recent_length": float(a[:, 2].mean()),
            "recent_speed": float(a[:, 3].mean())}


def _shown(hist: dict[str, Any], upd: dict[str, float] | None) -> dict[str, float | None]:
    """The progress bar's running means, last success rate and entropy temperature (None: not yet)."""
    r = _recent(hist)
    succ = hist["eval"][-1]["success"] if hist["eval"] else None
    alpha = None if upd is None else upd["alpha"]
    return {"ret": r["recent_return"], "v": r["recent_speed"], "succ": succ, "alpha": alpha}


def _summary(step: int, wall: float, hist: dict[str, Any], out_dir: Path, resumed_from: int | None) -> dict[str, Any]:
    return {"step": int(step), "wall_time_s": float(wall), "out_dir": str(out_dir), "resumed_from": resumed_from,
            "eval": hist["eval"][-1] if hist["eval"] else None, **_recent(hist)}
