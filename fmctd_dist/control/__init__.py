"""Low-level control: the PD waypoint follower that executes PointMaze plans, and the subgoal
schedule that feeds a goal-conditioned policy on AntMaze."""

from fmctd_dist.control.pd import PDController, repeat_waypoints
from fmctd_dist.control.subgoal import SubgoalTracker

__all__ = ["PDController", "SubgoalTracker", "repeat_waypoints"]
