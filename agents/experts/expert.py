"""The routing expert: plans prize-collecting routes and follows them one hop at a time.

Modes:

- ``"open_loop"``: plan once over the steps left in the episode and follow the routes. The
  plan is redone when it can no longer be followed: a robot is not where the plan expected
  (the collision resolver blocked it) or a robot can no longer reach its remaining stops in
  the steps left.
- ``"receding"``: plan every step over ``horizon`` steps (the paper's K) and take the first
  hop of each route; fewer near the end of the episode, unless ``clock=False``: a planner blind
  to the clock always plans over ``horizon`` steps, so its action is a function of where the
  robots and the points are (what a policy without the time sees), not of the steps left.

Information (exploration):

- ``"full"`` (omniscient, the paper's teacher for imitation): plans on the true map with every
  point of interest, discovered or not. In coverage this is the only kind.
- ``"known"`` (fair): plans on what the team has discovered only
  (:meth:`marl_cover.env.CoverageSnapshot.known`): the known graph, the discovered unvisited
  points of interest, and one prize for each frontier waypoint (a discovered waypoint next to
  undiscovered ones), so that routes also push into the unknown.
- ``"expected"`` (the floor plan, not the points): plans on the true map, where the discovered
  unvisited points of interest are worth one prize each and every undiscovered waypoint the
  share of the discovered waypoints that are points of interest (what it is expected to hold).
  Its routes lead into the unknown where the map holds many waypoints, not to the points hidden
  there, so its actions depend on what a robot can see far less than the omniscient expert's.

Fallback (it never crashes an episode): a robot whose route is empty (nothing in reach, an
empty, failed or infeasible solve) takes the greedy action toward the nearest unvisited point
of interest within ``fallback_reach`` hops (default: anywhere; the expert knows the whole map,
and the horizon bounds only its plans), staying if there is none; the points are those of
the snapshot it plans on (:meth:`RoutingExpert.visible`: with ``"known"`` the frontier counts,
with ``"expected"`` every undiscovered waypoint). Each step's fallbacks and re-plans are in
:attr:`RoutingExpert.info`; totals in :attr:`RoutingExpert.counts`.

The expert reads only :meth:`marl_cover.env.CoverageEnv.snapshot`, never the env's private
state.
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import replace
from typing import Any

import numpy as np

from marl_cover.agents.experts.backends import BACKENDS, solve
from marl_cover.agents.experts.problem import RoutingProblem, build_problem
from marl_cover.env import CoverageSnapshot
from marl_cover.graph import SpatialGraph

MODES = ("open_loop", "receding")
INFORMATION = ("full", "known", "expected")


def step_toward(graph: SpatialGraph, robot_node: np.ndarray, goals: np.ndarray) -> np.ndarray:
    """Action of each robot for one hop along a shortest path to its goal (``-1``: stay).

    Ties go to the lowest action slot (east, north, west, south).
    """
    return lowest_action(shortest_moves(graph, robot_node, goals))


def shortest_moves(graph: SpatialGraph, robot_node: np.ndarray, goals: np.ndarray) -> np.ndarray:
    """Every action that starts a shortest path to each robot's goal, as a bit mask ``(R,)``.

    Bit ``a`` is set when action ``a`` is one hop along some shortest path; bit 0 (stay) alone
    when the goal is ``-1``, the robot's own waypoint or out of reach. :func:`step_toward`
    takes the lowest of them; a plan is worth as much whichever one a robot takes, so they are
    the labels a learner may match (``dagger.ties``).
    """
    mask = np.ones(len(robot_node), dtype=np.int64)  # stay
    moving = np.flatnonzero((goals >= 0) & (goals != robot_node))
    if len(moving) == 0:
        return mask
    dist = graph.hop_distances(goals[moving])  # (M, N)
    nbr = graph.neighbors[robot_node[moving]]  # (M, 4)
    d = np.where(nbr >= 0, dist[np.arange(len(moving))[:, None], nbr.clip(min=0)], np.inf)
    nearest = d.min(axis=1, keepdims=True)  # (M, 1)
    on_path = np.isfinite(nearest) & (d == nearest)  # (M, 4)
    bits = (on_path * (1 << np.arange(1, 5))).sum(axis=1)
    mask[moving] = np.where(bits > 0, bits, 1)
    return mask


def lowest_action(mask: np.ndarray) -> np.ndarray:
    """The lowest action of each bit mask of :func:`shortest_moves`, ``(R,)`` int64."""
    mask = np.asarray(mask, dtype=np.int64)
    return np.log2(mask & -mask).astype(np.int64)


def greedy_goals(snapshot: CoverageSnapshot, robots: np.ndarray, limit: float) -> np.ndarray:
    """Nearest unvisited point of interest of each listed robot within ``limit`` hops (-1)."""
    goals = np.full(len(robots), -1, dtype=np.int64)
    targets = np.flatnonzero(snapshot.unvisited_interest)
    if len(robots) == 0 or len(targets) == 0:
        return goals
    dist = snapshot.graph.hop_distances(snapshot.robot_node[robots], limit=limit)[:, targets]
    best = np.argmin(dist, axis=1)  # lowest map index among the nearest
    found = np.isfinite(dist[np.arange(len(robots)), best])
    goals[found] = targets[best[found]]
    return goals


class RoutingExpert:
    """A routing expert policy over a coverage environment's snapshot.

    Args:
        backend: ``"pyvrp"`` or ``"ortools"``.
        mode: ``"open_loop"`` or ``"receding"``.
        horizon: Planning horizon in steps for ``"receding"`` (the paper's K), and the greedy
            fallback's reach in both modes (``None``: unlimited).
        time_limit: Seconds per solve.
        seed: Solver seed (PyVRP).
        fallback_reach: How far the greedy fallback looks, in hops (``None``: the whole map).
        warm_start: Start each solve from the previous plan (receding horizon, re-plans).
        max_iterations: Stop each solve after this many iterations (PyVRP) or solutions
            (OR-Tools) instead of ``time_limit``: deterministic plans, for datasets.
        information: ``"full"`` (omniscient) or ``"known"`` (only what the team discovered).
        clock: ``False`` (receding mode only): plan over ``horizon`` steps at every step, even
            when fewer are left in the episode.
    """

    def __init__(
        self,
        backend: str = "pyvrp",
        mode: str = "open_loop",
        horizon: int | None = None,
        time_limit: float = 0.9,
        seed: int = 0,
        max_iterations: int | None = None,
        warm_start: bool = True,
        fallback_reach: int | None = None,
        information: str = "full",
        clock: bool = True,
    ) -> None:
        if backend not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        if mode == "receding" and (horizon is None or horizon < 1):
            raise ValueError("mode 'receding' needs a horizon >= 1")
        if not clock and mode != "receding":
            raise ValueError("clock=False needs mode 'receding' (a plan over a fixed horizon)")
        if information not in INFORMATION:
            raise ValueError(f"information must be one of {INFORMATION}, got {information!r}")
        if time_limit < 0:
            raise ValueError(f"time_limit must be >= 0, got {time_limit}")
        self.backend = backend
        self.mode = mode
        self.horizon = horizon
        self.time_limit = time_limit
        self.seed = seed
        self.max_iterations = max_iterations
        self.warm_start = warm_start
        self.fallback_reach = fallback_reach
        self.information = information
        self.clock = clock
        self.counts: Counter[str] = Counter()
        self.info: dict[str, Any] = {}
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        """Forgets the plan (call at each episode start); ``seed`` re-seeds the solver."""
        if seed is not None:
            self.seed = seed
        self._routes: list[list[int]] | None = None  # waypoint stops per robot
        self._expected: np.ndarray | None = None
        self.accept = np.zeros(0, dtype=np.int64)  # set by each act_snapshot
        self.counts = Counter()

    # ------------------------------------------------------------------ planning
    def plan(self, snapshot: CoverageSnapshot) -> list[list[int]]:
        """Solves the routing problem of ``snapshot``; waypoint stops per robot.

        A solve that fails or returns an infeasible plan gives empty routes (counted as
        ``"failed_solve"``).
        """
        horizon = self.horizon if self.mode == "receding" else None
        problem = build_problem(snapshot, horizon, self.clock, self.value(snapshot))
        initial = self._warm_start(problem)
        start = time.perf_counter()
        try:
            routes = solve(
                problem, self.backend, self.time_limit, self.seed, self.max_iterations, initial
            )
        except Exception:  # noqa: BLE001 (any solver failure falls back to greedy)
            routes = [[] for _ in range(problem.num_robots)]
            self.counts["failed_solve"] += 1
        self.counts["solves"] += 1
        self.counts["solve_ms"] += int(1000 * (time.perf_counter() - start))
        if not problem.is_feasible(routes):
            self.counts["failed_solve"] += 1
            routes = [[] for _ in range(problem.num_robots)]
        return self._to_waypoints(problem, routes)

    def _warm_start(self, problem: RoutingProblem) -> list[list[int]] | None:
        """The previous plan in the new problem's candidate indices, cut to fit the budgets."""
        if not self.warm_start or self._routes is None:
            return None
        index = {int(w): k for k, w in enumerate(problem.candidates)}
        routes = []
        for r, route in enumerate(self._routes):
            stops = [index[w] for w in route if w in index]
            while stops and problem.route_length(r, stops) > problem.budget[r]:
                stops.pop()
            routes.append(stops)
        return routes if problem.is_feasible(routes) else None

    @staticmethod
    def _to_waypoints(problem: RoutingProblem, routes: list[list[int]]) -> list[list[int]]:
        return [[int(problem.candidates[k]) for k in route] for route in routes]

    def _needs_replan(self, snapshot: CoverageSnapshot) -> bool:
        """A plan stays feasible while every robot moves as planned: each step shortens every
        route by one hop (dropping stops others visited only shortens it further). A robot
        that is not where the plan expected (blocked) makes it stale."""
        return (
            self._routes is None
            or self._expected is None
            or not np.array_equal(self._expected, snapshot.robot_node)
        )

    # ------------------------------------------------------------------ acting
    def act_snapshot(
        self, snapshot: CoverageSnapshot, active: np.ndarray | None = None
    ) -> np.ndarray:
        """Actions ``(R,)`` for the current snapshot.

        Args:
            snapshot: The state to act on.
            active: ``(R,)`` bool, the robots whose actions will be carried out (robots that
                decide asynchronously, as in :mod:`marl_cover.continuous`); the others are
                expected to stay where the snapshot puts them. ``None``: every robot.
        """
        snapshot = self.visible(snapshot)
        replanned = False
        if self._routes is not None:  # drop stops visited since (by anyone)
            self._routes = [[s for s in route if not snapshot.visited[s]] for route in self._routes]
        if self.mode == "receding" or self._needs_replan(snapshot):
            self._routes = self.plan(snapshot)
            replanned = True
            if self.mode == "open_loop" and self._expected is not None:
                self.counts["replans"] += 1
        routes = self._routes
        assert routes is not None  # planned above when there were none (_needs_replan)
        goals = np.array([route[0] if route else -1 for route in routes], dtype=np.int64)
        fallback = np.flatnonzero(goals < 0)
        limit = np.inf if self.fallback_reach is None else self.fallback_reach
        goals[fallback] = greedy_goals(snapshot, fallback, limit)
        #: (R,) bit masks of the actions as good as ``actions`` (:func:`shortest_moves`)
        self.accept = shortest_moves(snapshot.graph, snapshot.robot_node, goals)
        actions = lowest_action(self.accept)
        self.counts["fallback_steps"] += len(fallback)
        self.info = {"fallback": len(fallback), "replanned": replanned}
        targets = np.where(
            actions > 0,
            snapshot.graph.neighbors[snapshot.robot_node, (actions - 1).clip(min=0)],
            snapshot.robot_node,
        )
        if active is not None:  # the others keep their waypoints
            targets = np.where(active, targets, snapshot.robot_node)
        self._expected = targets
        return actions

    def visible(self, snapshot: CoverageSnapshot) -> CoverageSnapshot:
        """The snapshot the expert plans on: unchanged (``"full"``), the known graph with the
        discovered points of interest and the frontier as prizes (``"known"``), or the true
        graph with the discovered points of interest and the undiscovered waypoints as prizes
        (``"expected"``; their worth: :meth:`value`)."""
        if self.information == "full":
            return snapshot
        if self.information == "expected":
            expected = (snapshot.interest & snapshot.discovered) | ~snapshot.discovered
            return replace(snapshot, interest=expected)
        frontier = snapshot.frontier
        known = snapshot.known()
        return replace(known, interest=known.interest | frontier)

    def value(self, snapshot: CoverageSnapshot) -> np.ndarray | None:
        """``(N,)`` worth of each waypoint's prize (``"expected"``: 1 where discovered, else
        the share of the discovered waypoints that are points of interest); ``None``: 1 each."""
        if self.information != "expected":
            return None
        num_discovered = int(np.count_nonzero(snapshot.discovered))
        share = np.count_nonzero(snapshot.interest & snapshot.discovered) / max(num_discovered, 1)
        return np.where(snapshot.discovered, 1.0, share)

    def act_env(self, env: Any) -> dict[str, int]:
        """Actions keyed by agent name, from ``env.snapshot()``."""
        actions = self.act_snapshot(env.snapshot())
        return dict(zip(env.possible_agents, actions.tolist(), strict=True))
