"""Policies, routing experts, GNN models, training, evaluation and the command line.

Installed as ``marl_cover.agents``; its subpackages, by role:

=============  ===============================================================================
baselines      greedy (nearest unvisited point within K hops), its tie rules, the omniscient
               assignment planner (numpy and scipy only)
experts        prize-collecting routing experts on PyVRP or OR-Tools (the ``expert`` extra)
models         the aggregation GNN, its policies, checkpoints and the shipped models (torch)
planners       one-step and decentralized rollouts on top of a GNN
training       expert datasets, behaviour cloning, DAgger, MAPPO, weight averaging (torch)
evaluation     paired evaluation over fixed seeds, upper bounds on any policy, comparisons,
               the paper's published numbers
mission        the discrete policies flying robots with dynamics
cli            the ``marl-cover`` command line
=============  ===============================================================================
"""

from marl_cover.agents.baselines import AssignmentPolicy, CentralizedGreedyPolicy, GreedyPolicy

__all__ = ["AssignmentPolicy", "CentralizedGreedyPolicy", "GreedyPolicy"]
