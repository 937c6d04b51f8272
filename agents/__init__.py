"""Policies, experts and training code for marl-cover (baselines need only numpy and scipy)."""

from agents.greedy import CentralizedGreedyPolicy, GreedyPolicy

__all__ = ["CentralizedGreedyPolicy", "GreedyPolicy"]
