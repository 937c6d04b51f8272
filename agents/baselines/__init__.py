"""Baseline policies that need only numpy and scipy: greedy on each robot's ego-graph, and the
spread rule that breaks near-ties away from teammates."""

from marl_cover.agents.baselines.greedy import CentralizedGreedyPolicy, GreedyPolicy

__all__ = ["CentralizedGreedyPolicy", "GreedyPolicy"]
