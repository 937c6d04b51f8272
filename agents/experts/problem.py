"""The prize-collecting routing problem behind the routing expert.

Each robot starts at its own waypoint; routes are open (they end anywhere); each robot's route
is at most ``budget[r]`` hops long; every unvisited point of interest within reach carries one
prize (or a share of one, ``value``, for a point the planner only expects). Maximising the
prizes collected (and, second, minimising hops) is the coverage problem with collisions
ignored. Hop distances come from breadth-first searches from the robots and the
candidate points only, truncated at the largest budget: never an all-pairs map matrix.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from marl_cover.env import CoverageSnapshot

#: Stand-in for "unreachable within the budget" in integer distance matrices.
UNREACHABLE = 1_000_000
#: Prize of one point of interest in solver units: above any route length, so the solvers
#: maximise the points first and minimise hops second.
PRIZE = 10_000


@dataclass(frozen=True)
class RoutingProblem:
    """Locations ``0..R-1`` are the robots' waypoints, ``R..R+C-1`` the candidate points.

    Attributes:
        robot_node: ``(R,)`` waypoint of each robot.
        candidates: ``(C,)`` waypoints of the candidate points of interest.
        distance: ``(R + C, R + C)`` int64 hop distances, :data:`UNREACHABLE` beyond the budget.
        budget: ``(R,)`` most hops each robot may travel.
        prize: ``(C,)`` int64 prize of each candidate in solver units (:data:`PRIZE` for a
            point of interest); ``None``: :data:`PRIZE` each.
    """

    robot_node: np.ndarray
    candidates: np.ndarray
    distance: np.ndarray
    budget: np.ndarray
    prize: np.ndarray | None = None

    def prizes(self) -> np.ndarray:
        """``(C,)`` int64 prize of each candidate."""
        if self.prize is None:
            return np.full(self.num_candidates, PRIZE, dtype=np.int64)
        return self.prize

    @property
    def num_robots(self) -> int:
        """Robots (routes) of the problem."""
        return len(self.robot_node)

    @property
    def num_candidates(self) -> int:
        """Candidate stops (points of interest within reach)."""
        return len(self.candidates)

    def route_length(self, robot: int, stops: list[int]) -> int:
        """Hops of robot ``robot`` visiting candidate indices ``stops`` in order."""
        path = [robot] + [self.num_robots + s for s in stops]
        return int(sum(self.distance[a, b] for a, b in zip(path[:-1], path[1:], strict=True)))

    def is_feasible(self, routes: list[list[int]]) -> bool:
        """Whether candidate-index routes respect the budgets and visit each point once."""
        flat = [s for route in routes for s in route]
        if len(flat) != len(set(flat)):
            return False
        return all(self.route_length(r, route) <= self.budget[r] for r, route in enumerate(routes))


def build_problem(
    snapshot: CoverageSnapshot,
    horizon: int | None = None,
    clock: bool = True,
    value: np.ndarray | None = None,
) -> RoutingProblem:
    """The routing problem of the current state.

    Args:
        snapshot: The environment's public snapshot.
        horizon: Plan over at most this many steps (receding horizon); ``None`` plans over the
            steps left in the episode (open loop).
        clock: ``False``: plan over ``horizon`` steps even when fewer are left in the episode
            (a planner blind to the clock, whose plan depends only on where the robots and the
            points are).
        value: ``(N,)`` worth of each waypoint's prize, in points of interest (1: a known
            point; less for one only expected there); only unvisited points of interest with a
            positive value are candidates. ``None``: 1 each.

    Raises:
        ValueError: ``clock=False`` without a ``horizon``.
    """
    steps_left = snapshot.max_steps - snapshot.num_steps
    if horizon is None:
        if not clock:
            raise ValueError("a plan blind to the clock (clock=False) needs a horizon")
        limit = steps_left
    else:
        limit = min(horizon, steps_left) if clock else horizon
    robots = snapshot.robot_node
    budget = np.full(len(robots), limit, dtype=np.int64)
    graph = snapshot.graph
    from_robots = graph.hop_distances(robots, limit=limit)  # (R, N)
    wanted = snapshot.unvisited_interest
    if value is not None:
        wanted = wanted & (value > 0)
    reachable = np.flatnonzero(wanted & (from_robots.min(axis=0) <= limit))
    from_points = graph.hop_distances(reachable, limit=limit)  # (C, N)
    locations = np.concatenate([robots, reachable])
    full = np.concatenate([from_robots, from_points])[:, locations]
    distance = np.where(np.isfinite(full), full, UNREACHABLE).astype(np.int64)
    prize = None if value is None else np.rint(PRIZE * value[reachable]).astype(np.int64)
    return RoutingProblem(robots.copy(), reachable, distance, budget, prize)
