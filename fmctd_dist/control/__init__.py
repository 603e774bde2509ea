"""Low-level control: the PD waypoint follower that executes PointMaze plans."""

from fmctd_dist.control.pd import PDController, repeat_waypoints

__all__ = ["PDController", "repeat_waypoints"]
