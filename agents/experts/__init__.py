"""Routing experts: prize-collecting multi-robot routing with OR-Tools or PyVRP."""

from agents.experts.backends import BACKENDS, solve
from agents.experts.expert import MODES, RoutingExpert
from agents.experts.local import LocalRoutingExpert
from agents.experts.problem import RoutingProblem, build_problem

__all__ = [
    "BACKENDS",
    "MODES",
    "LocalRoutingExpert",
    "RoutingExpert",
    "RoutingProblem",
    "build_problem",
    "solve",
]
