"""Soft actor-critic (Haarnoja et al. 2018) in PyTorch, small enough to read in one sitting.

Twin Q critics with polyak-averaged targets, a tanh-squashed Gaussian actor, automatic
entropy tuning, a numpy replay buffer. The twin critics are one ensemble (weights
[2, in, out], one ``baddbmm`` per layer): on one CPU thread that halves the kernel calls
of the update, which dominates training time. All randomness is explicit: network init
from ``torch.manual_seed(seed)`` inside a forked RNG, action noise from the agent's
``torch.Generator``, batch indices from the caller's numpy Generator; so a seed fixes
every update bitwise (on one device and thread count).
"""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from fmctd_dist.families.maze.expert.config import SACConfig

LOG_STD_MIN, LOG_STD_MAX = -5.0, 2.0
ACTOR_OUT_SCALE = 0.01  # last actor layer starts near zero: mean ~0, std ~1 (as OGBench's SAC)


def mlp(sizes: list[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


class EnsembleLinear(nn.Module):
    """E independent linear layers applied to x [E, B, in] -> [E, B, out] (nn.Linear's init per member)."""

    def __init__(self, ensemble: int, d_in: int, d_out: int):
        super().__init__()
        bound = 1.0 / math.sqrt(d_in)
        self.weight = nn.Parameter(torch.empty(ensemble, d_in, d_out).uniform_(-bound, bound))
        self.bias = nn.Parameter(torch.empty(ensemble, 1, d_out).uniform_(-bound, bound))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.baddbmm(self.bias, x, self.weight)


class TwinQ(nn.Module):
    """Q1, Q2 (s, a) -> [2, B]."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: list[int]):
        super().__init__()
        sizes = [obs_dim + act_dim, *hidden, 1]
        self.layers = nn.ModuleList(EnsembleLinear(2, sizes[i], sizes[i + 1]) for i in range(len(sizes) - 1))

    def forward(self, obs: torch.Tensor, act: torch.Tensor) -> torch.Tensor:
        x = torch.cat([obs, act], dim=-1).expand(2, -1, -1)  # [2, B, obs+act]
        for i, layer in enumerate(self.layers):
            x = layer(x)
            if i < len(self.layers) - 1:
                x = F.relu(x)
        return x.squeeze(-1)


class Actor(nn.Module):
    """Tanh-Gaussian policy: obs [B, obs_dim] -> action in (-1, 1)^act_dim."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: list[int]):
        super().__init__()
        self.net = mlp([obs_dim, *hidden, 2 * act_dim])
        with torch.no_grad():
            last = self.net[-1]
            last.weight.mul_(ACTOR_OUT_SCALE)
            last.bias.mul_(ACTOR_OUT_SCALE)
        self.obs_dim, self.act_dim = obs_dim, act_dim

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        mean, log_std = self.net(obs).chunk(2, dim=-1)
        return mean, log_std.clamp(LOG_STD_MIN, LOG_STD_MAX)

    def sample(self, obs: torch.Tensor, gen: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
        """Reparameterised sample and its log-probability [B] (tanh change of variables included)."""
        mean, log_std = self(obs)
        eps = torch.randn(mean.shape, generator=gen, dtype=mean.dtype, device=mean.device)
        u = mean + log_std.exp() * eps
        log_prob = (-0.5 * eps.square() - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)
        log_prob = log_prob - (2.0 * (math.log(2.0) - u - F.softplus(-2.0 * u))).sum(-1)  # log(1 - tanh(u)^2)
        return torch.tanh(u), log_prob

    @torch.no_grad()
    def act(self, obs: torch.Tensor) -> torch.Tensor:
        """Deterministic action tanh(mean) (what the expert uses)."""
        return torch.tanh(self(obs)[0])


class ReplayBuffer:
    """Ring buffer of float32 transitions.

    ``done`` is 1 only when the ant falls: time limits bootstrap (OGBench's main_sac.py marks
    them terminal, which teaches the critic a horizon the task does not have).
    """

    def __init__(self, capacity: int, obs_dim: int, act_dim: int):
        self.capacity = capacity
        self.obs = np.zeros((capacity, obs_dim), np.float32)
        self.next_obs = np.zeros((capacity, obs_dim), np.float32)
        self.act = np.zeros((capacity, act_dim), np.float32)
        self.rew = np.zeros(capacity, np.float32)
        self.done = np.zeros(capacity, np.float32)
        self.ptr = 0
        self.size = 0

    def add(self, obs: np.ndarray, act: np.ndarray, rew: float, next_obs: np.ndarray, done: bool) -> None:
        i = self.ptr
        self.obs[i], self.act[i], self.rew[i], self.next_obs[i], self.done[i] = obs, act, rew, next_obs, done
        self.ptr = (i + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    def sample(self, rng: np.random.Generator, batch: int) -> dict[str, torch.Tensor]:
        idx = rng.integers(0, self.size, batch)
        return {k: torch.from_numpy(getattr(self, k)[idx]) for k in ("obs", "act", "rew", "next_obs", "done")}

    def state_dict(self, keep: int) -> dict[str, Any]:
        """The newest ``keep`` transitions as tensors; the exact ring (same indices) when it all fits."""
        if keep >= self.size:
            idx, ptr = np.arange(self.size), self.ptr
        else:
            idx, ptr = (self.ptr - keep + np.arange(keep)) % self.capacity, keep % self.capacity  # oldest first
        out: dict[str, Any] = {k: torch.from_numpy(getattr(self, k)[idx].copy())
                               for k in ("obs", "act", "rew", "next_obs", "done")}
        out.update(ptr=int(ptr), size=int(len(idx)), seen=int(self.size))
        return out

    def load_state_dict(self, state: dict[str, Any]) -> None:
        n = int(state["size"])
        if n > self.capacity:
            state = {**state, **{k: state[k][-self.capacity:] for k in ("obs", "act", "rew", "next_obs", "done")}}
            n, state["ptr"] = self.capacity, 0
        for k in ("obs", "act", "rew", "next_obs", "done"):
            getattr(self, k)[:n] = state[k].numpy()
        self.size, self.ptr = n, int(state["ptr"]) % self.capacity


class SAC:
    """Actor, twin critics + targets, log temperature, and their Adam optimisers."""

    def __init__(self, obs_dim: int, act_dim: int, cfg: SACConfig, seed: int):
        self.cfg = cfg
        with torch.random.fork_rng(devices=[]):  # seeded init without touching the caller's global RNG
            torch.manual_seed(seed)
            self.actor = Actor(obs_dim, act_dim, list(cfg.hidden))
            self.critic = TwinQ(obs_dim, act_dim, list(cfg.hidden))
        self.critic_target = copy.deepcopy(self.critic).requires_grad_(False)
        self.log_alpha = nn.Parameter(torch.tensor(math.log(cfg.init_alpha)))
        self.target_entropy = -cfg.target_entropy_scale * act_dim
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=cfg.lr)
        self.critic_opt = torch.optim.Adam(self.critic.parameters(), lr=cfg.lr)
        self.alpha_opt = torch.optim.Adam([self.log_alpha], lr=cfg.lr)
        self.gen = torch.Generator().manual_seed(seed)
        self.updates = 0

    @property
    def alpha(self) -> float:
        return float(self.log_alpha.detach().exp())

    @torch.no_grad()
    def act(self, obs: np.ndarray, deterministic: bool = False) -> np.ndarray:
        """obs [obs_dim] -> action [act_dim] (sampled with the agent's generator unless deterministic)."""
        o = torch.as_tensor(obs, dtype=torch.float32)[None]
        a = self.actor.act(o) if deterministic else self.actor.sample(o, self.gen)[0]
        return a[0].numpy().astype(np.float64)

    def update(self, batch: dict[str, torch.Tensor]) -> dict[str, float]:
        """One gradient step on critics, actor and temperature, then the polyak target update."""
        obs, act, rew, next_obs, done = (batch[k] for k in ("obs", "act", "rew", "next_obs", "done"))
        alpha = self.log_alpha.detach().exp()
        with torch.no_grad():
            next_act, next_logp = self.actor.sample(next_obs, self.gen)
            next_q = self.critic_target(next_obs, next_act).min(0).values - alpha * next_logp
            target = rew + self.cfg.gamma * (1.0 - done) * next_q
        q = self.critic(obs, act)  # [2, B]
        critic_loss = (q - target).square().mean(1).sum()
        self.critic_opt.zero_grad(set_to_none=True)
        critic_loss.backward()
        self.critic_opt.step()

        self.critic.requires_grad_(False)  # the actor loss needs dQ/da, not dQ/dtheta
        new_act, logp = self.actor.sample(obs, self.gen)
        actor_loss = (alpha * logp - self.critic(obs, new_act).min(0).values).mean()
        self.actor_opt.zero_grad(set_to_none=True)
        actor_loss.backward()
        self.actor_opt.step()
        self.critic.requires_grad_(True)

        entropy = -logp.detach().mean()
        alpha_loss = self.log_alpha.exp() * (entropy - self.target_entropy)
        self.alpha_opt.zero_grad(set_to_none=True)
        alpha_loss.backward()
        self.alpha_opt.step()

        with torch.no_grad():
            for t, p in zip(self.critic_target.parameters(), self.critic.parameters()):
                t.lerp_(p, self.cfg.tau)
        self.updates += 1
        return {"critic_loss": float(critic_loss.detach()), "actor_loss": float(actor_loss.detach()),
                "q": float(q.detach().mean()), "entropy": float(entropy), "alpha": float(alpha)}

    def state_dict(self) -> dict[str, Any]:
        """Everything an exact resume needs (tensors and plain types: loads with weights_only=True)."""
        return {"actor": self.actor.state_dict(), "critic": self.critic.state_dict(),
                "critic_target": self.critic_target.state_dict(), "log_alpha": self.log_alpha.detach().clone(),
                "actor_opt": self.actor_opt.state_dict(), "critic_opt": self.critic_opt.state_dict(),
                "alpha_opt": self.alpha_opt.state_dict(), "gen": self.gen.get_state(), "updates": self.updates}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.actor.load_state_dict(state["actor"])
        self.critic.load_state_dict(state["critic"])
        self.critic_target.load_state_dict(state["critic_target"])
        with torch.no_grad():
            self.log_alpha.copy_(state["log_alpha"])
        self.actor_opt.load_state_dict(state["actor_opt"])
        self.critic_opt.load_state_dict(state["critic_opt"])
        self.alpha_opt.load_state_dict(state["alpha_opt"])
        for opt in (self.actor_opt, self.critic_opt, self.alpha_opt):  # sac.lr may change between runs
            for group in opt.param_groups:
                group["lr"] = self.cfg.lr
        self.gen.set_state(state["gen"])
        self.updates = int(state["updates"])
