"""Training windows, sampled lazily (giant would be GBs if materialised).

A window is ``train_window + 1`` raw steps at any offset, subsampled every ``jump`` steps
(S-MCTD), normalised, and cut into tokens: token 0 = the first frame repeated (context),
tokens 1..P = the remaining ``train_window / jump`` frames, ``frame_stack`` per token.
"""

from __future__ import annotations

import numpy as np

from fmctd_dist.tokens import Normaliser, context_token, frames_to_tokens


class WindowSampler:
    """Draws [B, P+1, d*frame_stack] normalised token windows from frame states [E, S, d] (maze x, y; cube
    xyz; visual latents)."""

    def __init__(self, obs: np.ndarray, train_window: int, jump: int, frame_stack: int, normaliser: Normaliser,
                 start_balance: float = 0.0):
        e, s, _ = obs.shape
        assert train_window % (jump * frame_stack) == 0, "train_window must be a multiple of jump * frame_stack"
        assert s >= train_window + 1, f"episodes of {s} steps are shorter than a window of {train_window + 1}"
        self.obs = obs
        self.train_window, self.jump, self.frame_stack = train_window, jump, frame_stack
        self.normaliser = normaliser
        self.offsets_per_episode = s - train_window  # every offset, stride 1
        self.n_windows = e * self.offsets_per_episode
        self._cdf = start_balance_cdf(obs[:, : self.offsets_per_episode], start_balance) if start_balance else None

    @property
    def n_tokens(self) -> int:
        return self.train_window // (self.jump * self.frame_stack) + 1

    def windows(self, index: np.ndarray) -> np.ndarray:
        """Window ids [B] (episode * offsets + offset) -> tokens [B, P+1, D]."""
        ep, off = np.divmod(np.asarray(index, dtype=np.int64), self.offsets_per_episode)
        steps = off[:, None] + np.arange(0, self.train_window + 1, self.jump)[None, :]  # [B, F+1]
        frames = self.normaliser.normalise(self.obs[ep[:, None], steps])  # [B, F+1, 2]
        ctx = context_token(frames[:, 0], self.frame_stack)
        return np.concatenate([ctx, frames_to_tokens(frames[:, 1:], self.frame_stack)], axis=1).astype(np.float32)

    def sample(self, rng: np.random.Generator, batch: int) -> np.ndarray:
        if self._cdf is None:
            return self.windows(rng.integers(0, self.n_windows, size=batch))
        return self.windows(np.searchsorted(self._cdf, rng.random(batch), side="right"))


BALANCE_BIN = 1.0  # world units: the grid on which start density is counted (a quarter of a maze cell)


def start_balance_cdf(starts: np.ndarray, alpha: float) -> np.ndarray:
    """Cumulative sampling weights [E*O] of windows whose first frames are ``starts`` [E, O, 2].

    A window is drawn with weight count(its start's grid cell)**-alpha, so rarely visited starts
    (a dead-end corner the oracle only touches on its way back) are seen more often. Why it is
    safe: the weight depends on the start alone, so p(trajectory | start), the only thing a
    planner that inpaints the start samples from, is unchanged; only the marginal of starts moves.
    alpha 0 = uniform (Janner's), 1 = every occupied grid cell equally often.
    """
    xy = starts.reshape(-1, starts.shape[-1])
    ij = np.floor(xy / BALANCE_BIN).astype(np.int64)
    _, inverse, counts = np.unique(ij, axis=0, return_inverse=True, return_counts=True)
    w = counts[inverse.reshape(-1)].astype(np.float64) ** -alpha
    cdf = np.cumsum(w)
    return cdf / cdf[-1]


class TrainData:
    """What the training loop needs: train sampler, fixed validation batches, digest, normaliser."""

    def __init__(self, train: WindowSampler, val: WindowSampler, digest: str, seed: int,
                 provenance: dict | None = None, position_readout=None, wall_depth=None):
        self.train, self.val = train, val
        self.normaliser = train.normaliser
        self.digest, self.seed = digest, seed
        self.provenance = provenance or {}  # extra manifest fields the dataset asks a model to keep (visual: its VAE)
        self.position_readout = position_readout  # cfg -> (frames -> positions, provenance); None: frames have none
        self.wall_depth = wall_depth  # cfg -> (frames -> depth inside walls, provenance); None: no maze walls

    @property
    def n_tokens(self) -> int:
        return self.train.n_tokens

    def sample(self, rng: np.random.Generator, batch: int) -> np.ndarray:
        return self.train.sample(rng, batch)

    def val_batches(self, n: int, batch: int) -> list[np.ndarray]:
        """The same n batches every call (fixed seed), so validation losses are comparable."""
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, 0x5A11D]))
        return [self.val.sample(rng, batch) for _ in range(n)]


def train_data(cfg, dataset) -> TrainData:
    """Build train/val samplers for ``cfg`` (jump, window, frame stack) over a NavigateDataset."""
    kw = dict(train_window=cfg.data.train_window, jump=cfg.jump, frame_stack=cfg.model.frame_stack,
              normaliser=dataset.normaliser)
    train = WindowSampler(dataset.train, **kw, start_balance=cfg.train.start_balance)
    return TrainData(train, WindowSampler(dataset.val, **kw), dataset.digest, cfg.data.seed,  # val stays uniform
                     getattr(dataset, "provenance", None), getattr(dataset, "position_readout", None),
                     getattr(dataset, "wall_depth", None))
