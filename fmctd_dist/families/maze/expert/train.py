"""SAC training loop for the ant direction expert, resumable and deterministic from a seed.

One env step, then ``updates_per_step`` SAC updates (after ``start_steps`` uniform random
steps). Every ``ckpt_every`` steps it writes model.pt + manifest.json (the actor: what
dataset generation needs) and train_state.pt (networks, optimisers, every RNG, the env's
MuJoCo state mid-episode, and the newest ``buffer_save`` replay transitions). Rerunning
continues from there; when the saved buffer holds every transition seen, the resumed run
is bitwise the uninterrupted one, otherwise it continues on the newest transitions only.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from fmctd_dist.families.maze.expert.config import AntExpertConfig
from fmctd_dist.config import git_sha
from fmctd_dist.families.maze.expert.direction_env import ACT_DIM, OBS_DIM, AntDirectionEnv
from fmctd_dist.families.maze.expert.evaluate import evaluate_directions, make_eval_env
from fmctd_dist.artifacts import MANIFEST_FILE
from fmctd_dist.families.maze.expert.expert import read_expert_manifest, save_expert
from fmctd_dist.families.maze.expert.sac import SAC, ReplayBuffer
from fmctd_dist.device import set_threads
from fmctd_dist.errors import CheckpointError
from fmctd_dist.resume import Clock, check_resume, load_train_state, save_train_state

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
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, RNG_STREAM])))
    step, wall, resumed_from = 0, 0.0, None
    hist: dict[str, Any] = {"episodes": [], "eval": [], "updates": []}  # [step, return, length, speed] / ...
    ep = {"ret": 0.0, "len": 0, "speed": 0.0}

    state = load_train_state(out_dir)
    if state is not None:
        check_resume(out_dir, "ant expert", "expert.out", state["config"], cfg.to_dict(), RESUME_FIELDS)
        agent.load_state_dict(state["agent"])
        buffer.load_state_dict(state["buffer"])
        rng.bit_generator.state = state["numpy_rng"]
        obs = env.set_state(state["env"])
        step, wall, hist, ep = int(state["step"]), float(state["wall_time_s"]), state["history"], state["episode"]
        resumed_from = step
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

    def evaluate() -> None:
        agent.actor.eval()
        m = evaluate_directions(lambda o: agent.act(o, deterministic=True), cfg.env, cfg.eval, env=eval_env)
        agent.actor.train()
        hist["eval"].append({"step": step, **m})

    def save() -> None:
        last_eval = hist["eval"][-1] if hist["eval"] else None
        save_expert(out_dir, agent.actor, {
            "config": cfg.to_dict(), "env_steps": step, "updates": agent.updates, "wall_time_s": wall,
            "git_sha": git_sha(), "seed": seed, "metrics": {"eval": last_eval, **_recent(hist)},
            "eval_history": hist["eval"], "ogbench_env": "ogbench.online_locomotion.ant.AntEnv (open arena)",
        })
        save_train_state(out_dir, {
            "agent": agent.state_dict(), "buffer": buffer.state_dict(ec.buffer_save), "env": env.get_state(),
            "numpy_rng": rng.bit_generator.state, "step": step, "wall_time_s": wall, "history": hist,
            "episode": ep, "config": cfg.to_dict(),
        })

    bar = tqdm(total=ec.max_steps, initial=step, disable=not progress, desc="ant expert", dynamic_ncols=True)
    clock = Clock(wall)
    t_log = clock.started
    n_log, last_update = 0, None
    while step < ec.max_steps:
        if step < ec.start_steps:
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
            hist["episodes"].append([step + 1, ep["ret"], ep["len"], ep["speed"] / ep["len"]])
            ep = {"ret": 0.0, "len": 0, "speed": 0.0}
            obs = env.reset()
        step += 1
        n_log += 1
        if step > ec.start_steps:  # one update per step from the first policy step on
            for _ in range(ec.updates_per_step):
                last_update = agent.update(buffer.sample(rng, cfg.sac.batch_size))
        if step % ec.log_every == 0 or step == ec.max_steps:
            now = time.perf_counter()
            if last_update is not None:
                hist["updates"].append([step, last_update["critic_loss"], last_update["q"], last_update["alpha"]])
            bar.set_postfix(_postfix(hist, last_update, n_log / (now - t_log)), refresh=False)
            bar.update(n_log)
            n_log, t_log = 0, now
        if (cfg.eval.every > 0 and step % cfg.eval.every == 0) or step == ec.max_steps:
            evaluate()
        if step % ec.ckpt_every == 0 or step == ec.max_steps:
            clock.lap()
            wall = clock.wall_s
            save()
    bar.close()
    env.close()
    eval_env.close()
    return _summary(step, wall, hist, out_dir, resumed_from)


def _recent(hist: dict[str, Any]) -> dict[str, Any]:
    eps = hist["episodes"][-RECENT:]
    if not eps:
        return {"recent_return": None, "recent_length": None, "recent_speed": None}
    a = np.asarray(eps, dtype=np.float64)
    return {"recent_return": float(a[:, 1].mean()), "recent_length": float(a[:, 2].mean()),
            "recent_speed": float(a[:, 3].mean())}


def _postfix(hist: dict[str, Any], upd: dict[str, float] | None, steps_s: float) -> dict[str, str]:
    r = _recent(hist)
    out = {"ret": "-" if r["recent_return"] is None else f"{r['recent_return']:.0f}",
           "v": "-" if r["recent_speed"] is None else f"{r['recent_speed']:.2f}"}
    if hist["eval"]:
        out["succ"] = f"{hist['eval'][-1]['success']:.2f}"
    if upd is not None:
        out["alpha"] = f"{upd['alpha']:.3f}"
    out["steps_s"] = f"{steps_s:.0f}"
    return out


def _summary(step: int, wall: float, hist: dict[str, Any], out_dir: Path, resumed_from: int | None) -> dict[str, Any]:
    return {"step": int(step), "wall_time_s": float(wall), "out_dir": str(out_dir), "resumed_from": resumed_from,
            "eval": hist["eval"][-1] if hist["eval"] else None, **_recent(hist)}
