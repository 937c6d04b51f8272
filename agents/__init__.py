"""Policies, routing experts, GNN models, training, evaluation and the command line.

Installed as ``marl_cover.agents``; its subpackages, by role:

=============  ===============================================================================
baselines      greedy (nearest unvisited point within K hops) and its tie rules (numpy only)
experts        prize-collecting routing experts on PyVRP or OR-Tools (the ``expert`` extra)
models         the aggregation GNN, its policies, checkpoints and the shipped models (torch)
planners       one-step and decentralized rollouts on top of a GNN
training       expert datasets, behaviour cloning, DAgger, MAPPO, weight averaging (torch)
evaluation     paired evaluation over fixed seeds, comparisons, the paper's published numbers
mission        the discrete policies flying robots with dynamics
cli            the ``marl-cover`` command line
=============  ===============================================================================
"""

from marl_cover.agents.baselines import CentralizedGreedyPolicy, GreedyPolicy

__all__ = ["CentralizedGreedyPolicy", "GreedyPolicy"]
