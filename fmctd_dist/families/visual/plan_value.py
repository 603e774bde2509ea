"""The visual planner's plan value: the maze rule on the estimator's positions of a latent plan.

Plans are latents [B, F, D]; the maze value (reach the goal early within ``goal_radius``, no step
longer than ``warp_threshold``; docs/reference.md §4) is asked of their estimated (x, y), with the start
and goal latents read the same way. This is our reading: the paper does not give the visual value
rule (docs/reference.md §14). The plan handed to the controller stays in latents (cut at the reach, the
goal latent last), so the inverse dynamics follows what the model sampled.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from fmctd_dist.search.actions import Actions
from fmctd_dist.search.value_rule import MazeValue

PositionFn = Callable[[np.ndarray], np.ndarray]  # latents [..., D] -> world (x, y) [..., 2]


@dataclass(frozen=True)
class VisualValue:
    positions: PositionFn
    maze: MazeValue  # warp threshold and goal radius, world units

    def prepare(self, plans: np.ndarray, start: np.ndarray, actions: Actions) -> np.ndarray:
        return plans  # one agent, every latent dim guided: nothing to pin

    def values(self, plans: np.ndarray, start: np.ndarray, goal: np.ndarray,
               actions: Actions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Latent plans [B, F, D], start / goal latents [D] -> the maze rule's values, status, reach_t."""
        xy = self.positions(plans)  # [B, F, 2]
        return self.maze.values(xy, self.positions(start), self.positions(goal), actions)

    def output(self, plan: np.ndarray, reach_t: int, goal: np.ndarray) -> np.ndarray:
        return self.maze.output(plan, reach_t, goal)
