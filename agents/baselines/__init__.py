"""Baseline policies that need only numpy and scipy: greedy on each robot's ego-graph, the
spread rule that breaks near-ties away from teammates, and the omniscient assignment planner."""

from marl_cover.agents.baselines.assignment import AssignmentPolicy
from marl_cover.agents.baselines.greedy import CentralizedGreedyPolicy, GreedyPolicy

__all__ = ["AssignmentPolicy", "CentralizedGreedyPolicy", "GreedyPolicy"]
