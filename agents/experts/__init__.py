"""Routing experts: prize-collecting multi-robot routing with OR-Tools or PyVRP."""

from marl_cover.agents.experts.backends import BACKENDS, solve
from marl_cover.agents.experts.expert import MODES, RoutingExpert
from marl_cover.agents.experts.local import LocalRoutingExpert
from marl_cover.agents.experts.problem import RoutingProblem, build_problem

__all__ = [
    "BACKENDS",
    "MODES",
    "LocalRoutingExpert",
    "RoutingExpert",
    "RoutingProblem",
    "build_problem",
    "solve",
]
