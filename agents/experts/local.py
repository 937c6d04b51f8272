"""The local routing expert: receding-horizon routes planned from each robot's own view.

Robot ``r`` plans on what its ego-observation holds: the waypoints within ``horizon`` hops of
its own (on the known graph in exploration), the unvisited points of interest among them (and,
in exploration, the frontier waypoints among them, one prize each, as the fair expert counts
them), and the other robots standing on them. It solves the prize-collecting routing problem
of that view for itself and the robots it sees (as if they followed the same plan) and takes
the first hop of its own route. Each robot plans apart, so the plans need not agree. With
nothing to collect in view it stays, or (``fallback="random"``, greedy's rule) takes a
uniformly random available move.

It is a decentralized planner with exactly the information of a ``horizon``-hop policy (one
solve per robot and step), so it tells how much of the team expert's lead over such a policy
comes from what the policy cannot see: the team expert plans every route at once on the whole
map, and its fallback heads for the nearest point anywhere.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import replace
from typing import Any

import numpy as np

from marl_cover.agents.baselines.greedy import FALLBACKS
from marl_cover.agents.experts.expert import (
    RoutingExpert,
    greedy_goals,
    lowest_action,
    shortest_moves,
)
from marl_cover.env import CoverageSnapshot


class LocalRoutingExpert:
    """Each robot's first hop of a receding-horizon plan over its own ``horizon``-hop view.

    Args:
        horizon: Hops a robot sees and plans over (the policy's K).
        backend: ``"pyvrp"`` or ``"ortools"``.
        time_limit: Seconds per solve.
        seed: Solver seed and seed of ``fallback="random"`` (until :meth:`reset` gives one).
        max_iterations: Stop each solve after this many iterations (deterministic plans).
        clock: ``False``: plan over ``horizon`` steps even when fewer are left in the episode.
        fallback: ``"stay"`` or ``"random"`` when nothing is in view.
    """

    def __init__(
        self,
        horizon: int,
        backend: str = "pyvrp",
        time_limit: float = 0.15,
        seed: int = 0,
        max_iterations: int | None = None,
        clock: bool = True,
        fallback: str = "stay",
    ) -> None:
        if fallback not in FALLBACKS:
            raise ValueError(f"fallback must be one of {FALLBACKS}, got {fallback!r}")
        self.horizon = horizon
        self.fallback = fallback
        self.seed = seed
        self._planner = RoutingExpert(
            backend=backend,
            mode="receding",
            horizon=horizon,
            time_limit=time_limit,
            seed=seed,
            max_iterations=max_iterations,
            warm_start=False,
            clock=clock,
        )
        self.counts: Counter[str] = Counter()  # the planner's solve counters and the fallbacks
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        """Clears the counters (call at each episode start); ``seed`` re-seeds the solver and
        the fallback, as :meth:`RoutingExpert.reset` does."""
        if seed is not None:
            self.seed = seed
        self._rng = np.random.default_rng(self.seed)
        self._planner.reset(self.seed)
        self.counts = self._planner.counts

    def view(self, snapshot: CoverageSnapshot, robot: int) -> CoverageSnapshot:
        """What ``robot`` plans on: its ball of ``horizon`` hops on the known graph, the prizes
        in it, and the robots on it, ``robot`` first."""
        return self._view(snapshot.known(), snapshot.frontier, robot)

    def _view(self, known: CoverageSnapshot, frontier: np.ndarray, robot: int) -> CoverageSnapshot:
        distance = known.graph.hop_distances(known.robot_node[[robot]], limit=self.horizon)
        ball = np.isfinite(distance[0]) & known.discovered  # (N,)
        seen = np.flatnonzero(ball[known.robot_node])
        order = np.concatenate([[robot], seen[seen != robot]])
        interest = (known.interest | frontier) & ball
        view = replace(
            known, interest=interest, discovered=ball, robot_node=known.robot_node[order]
        )
        return view.known()

    def act_snapshot(self, snapshot: CoverageSnapshot) -> np.ndarray:
        """Actions ``(R,)``: each robot's first hop of the plan over its own view."""
        actions = np.zeros(len(snapshot.robot_node), dtype=np.int64)
        known, frontier = snapshot.known(), snapshot.frontier
        for robot in range(len(snapshot.robot_node)):
            view = self._view(known, frontier, robot)
            route = self._planner.plan(view)[0]
            goal = route[0] if route else int(greedy_goals(view, np.array([0]), np.inf)[0])
            if goal >= 0:
                moves = shortest_moves(view.graph, view.robot_node[:1], np.array([goal]))
                actions[robot] = lowest_action(moves)[0]
                continue
            self.counts["fallback_steps"] += 1
            if self.fallback == "random":
                available = np.flatnonzero(known.graph.neighbors[known.robot_node[robot]] >= 0)
                if len(available):
                    actions[robot] = int(self._rng.choice(available)) + 1
        return actions

    def act_env(self, env: Any) -> dict[str, int]:
        """Actions keyed by agent name, from ``env.snapshot()``."""
        actions = self.act_snapshot(env.snapshot())
        return dict(zip(env.possible_agents, actions.tolist(), strict=True))
