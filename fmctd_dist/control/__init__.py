"""Low-level control: the PD waypoint follower that executes PointMaze plans, and the subgoal
schedule + plan controller that feed a goal-conditioned policy on AntMaze."""

from fmctd_dist.control.ant_controller import AntPlanController, PlanRun, run_plan
from fmctd_dist.control.pd import PDController, repeat_waypoints
from fmctd_dist.control.subgoal import SubgoalTracker

__all__ = ["AntPlanController", "PDController", "PlanRun", "SubgoalTracker", "repeat_waypoints", "run_plan"]
