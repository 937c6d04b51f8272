"""An episode's random draws from the environment's generator: the points of interest and the
robots' start waypoints (or the ones ``reset``'s options fix, checked)."""

from __future__ import annotations

from typing import Any

import numpy as np

from marl_cover.errors import as_node_indices
from marl_cover.graph import SpatialGraph


def draw_interest(
    graph: SpatialGraph, rng: np.random.Generator, fraction: float, given: Any = None
) -> np.ndarray:
    """The points of interest, ``(num_nodes,)`` bool: ``fraction`` of the waypoints drawn
    without replacement, or the waypoints ``given`` (``options["interest_nodes"]``).

    Raises:
        ValueError: a given waypoint lies outside the map.
    """
    interest = np.zeros(graph.num_nodes, dtype=bool)
    if given is not None:
        nodes = check_nodes(graph, given, "interest_nodes")
    else:
        count = int(fraction * graph.num_nodes)
        nodes = rng.choice(graph.num_nodes, size=count, replace=False)
    interest[nodes] = True
    return interest


def draw_starts(
    graph: SpatialGraph, rng: np.random.Generator, num_robots: int, density: int, given: Any = None
) -> np.ndarray:
    """Start waypoints, ``(num_robots,)`` int64, distinct: drawn from a breadth-first ball of at
    least ``density * num_robots`` waypoints around a random waypoint, or ``given``
    (``options["robot_nodes"]``).

    Raises:
        ValueError: the given waypoints are not one distinct waypoint per robot, or the team
            does not fit on the map or on the component drawn.
    """
    r = num_robots
    if given is not None:
        nodes = check_nodes(graph, given, "robot_nodes")
        if len(nodes) != r or len(np.unique(nodes)) != r:
            raise ValueError(
                f"options['robot_nodes'] must hold {r} distinct waypoints, got {given}"
            )
        return nodes
    if graph.num_nodes < r:
        raise ValueError(f"{r} robots do not fit on a map of {graph.num_nodes} waypoints")
    centre = int(rng.integers(graph.num_nodes))
    ball = graph.bfs_ball(centre, density * r)
    if len(ball) < r:
        raise ValueError(
            f"the component around waypoint {centre} has {len(ball)} waypoints, fewer than "
            f"the {r} robots"
        )
    return rng.choice(ball, size=r, replace=False).astype(np.int64)


def check_nodes(graph: SpatialGraph, given: Any, key: str) -> np.ndarray:
    """``given`` as waypoint indices ``(n,)`` int64.

    Raises:
        ValueError: an entry that is not an integer, or an index outside the map, naming the
            option ``key`` and the entry.
    """
    nodes = as_node_indices(given, f"options[{key!r}]")
    outside = np.flatnonzero((nodes < 0) | (nodes >= graph.num_nodes))
    if len(outside):
        i = int(outside[0])
        raise ValueError(
            f"options[{key!r}] holds a waypoint outside [0, {graph.num_nodes}): "
            f"entry {i} is {nodes[i]}"
        )
    return nodes
