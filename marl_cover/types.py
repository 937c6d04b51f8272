"""The environment's containers: what a step returns and did, and a read-only snapshot of an
episode for planners and experts (shapes in each field's description)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from marl_cover.discovery import frontier_of, known_neighbors
from marl_cover.graph import SpatialGraph

#: What ``step`` returns: observations, rewards, terminations, truncations, infos by agent.
StepResult = tuple[
    dict[str, dict[str, np.ndarray]],
    dict[str, float],
    dict[str, bool],
    dict[str, bool],
    dict[str, dict[str, Any]],
]


@dataclass(frozen=True)
class Moves:
    """What one step did (:meth:`CoverageEnv.apply_actions`).

    Attributes:
        new_interest: Points of interest each robot visited first this step, ``(R,)`` int64.
        blocked: Robots the collision resolver kept from their target, ``(R,)`` bool.
        invalid: Robots whose action was masked out (a no-op), ``(R,)`` bool.
        terminated: Every point of interest has been visited.
        truncated: The episode has used its ``max_steps`` actions and is not terminated.
    """

    new_interest: np.ndarray
    blocked: np.ndarray
    invalid: np.ndarray
    terminated: bool
    truncated: bool


@dataclass(frozen=True)
class CoverageSnapshot:
    """A read-only copy of the environment's state, for planners and experts.

    Attributes:
        graph: The map of this episode.
        robot_node: Waypoint of each robot, ``(num_robots,)`` int64.
        interest: Points of interest of this episode, ``(num_nodes,)`` bool.
        visited: Waypoints visited so far, ``(num_nodes,)`` bool.
        num_steps: Actions taken so far.
        max_steps: Actions per episode.
        hops: Ego-graph radius.
        discovered: Waypoints known to the team, ``(num_nodes,)`` bool (all of them in
            coverage).
    """

    graph: SpatialGraph
    robot_node: np.ndarray
    interest: np.ndarray
    visited: np.ndarray
    num_steps: int
    max_steps: int
    hops: int
    discovered: np.ndarray

    @property
    def unvisited_interest(self) -> np.ndarray:
        """Points of interest not visited yet, ``(num_nodes,)`` bool."""
        return self.interest & ~self.visited

    @property
    def frontier(self) -> np.ndarray:
        """Discovered waypoints with an undiscovered neighbour, ``(num_nodes,)`` bool."""
        return frontier_of(self.graph, self.discovered)

    def known(self) -> CoverageSnapshot:
        """The snapshot as the team knows it (what a fair planner may use): the known graph,
        where undiscovered waypoints keep their indices but have no edges, and the points of
        interest among the discovered waypoints."""
        if self.discovered.all():
            return self
        graph = SpatialGraph(
            self.graph.positions,
            known_neighbors(self.graph, self.discovered),
            self.graph.cell_size,
            self.graph.cells,
        )
        return dataclasses.replace(self, graph=graph, interest=self.interest & self.discovered)
