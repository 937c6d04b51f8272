"""Upper bounds on any policy's reward in one episode, from its start (perfect information).

Both count the points of interest not visited at the start that the team could still visit in
``steps`` moves; no policy, centralized or not, visits more:

- :func:`reach_bound`: the points within ``steps`` hops of some robot's start.
- :func:`route_bound`: also counts moves. A robot visits at most one waypoint a move, and a
  waypoint ``j`` hops from its start no earlier than move ``j``: of the points it visits, at most
  ``steps - j + 1`` lie ``j`` or more hops from its start. The most points that robots so
  limited visit between them, each point once, is a maximum flow (source -> point -> the robot
  at the point's distance -> the robot one hop nearer ... -> sink), solved exactly by
  :func:`scipy.sparse.csgraph.maximum_flow`. Collisions and the shape of a walk are left out,
  so it is still a bound; it is never above :func:`reach_bound`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import dijkstra, maximum_flow

#: Robots whose distances are computed at once (a ``(chunk, num_waypoints)`` float64 array).
_CHUNK = 128


def reach_bound(
    adjacency: sparse.spmatrix, robot_node: np.ndarray, open_interest: np.ndarray, steps: int
) -> int:
    """The points of interest within ``steps`` hops of some robot.

    Args:
        adjacency: ``(N, N)`` the waypoint graph.
        robot_node: ``(R,)`` each robot's waypoint.
        open_interest: ``(N,)`` bool, the points of interest not visited yet.
        steps: Moves left.
    """
    hops = dijkstra(adjacency, indices=robot_node, unweighted=True, limit=steps, min_only=True)
    return int(np.count_nonzero((hops <= steps) & open_interest))


def route_bound(
    adjacency: sparse.spmatrix, robot_node: np.ndarray, open_interest: np.ndarray, steps: int
) -> int:
    """The most points of interest robots can visit between them when each visits at most
    ``steps - j + 1`` points ``j`` or more hops from its start (the module docstring).

    Args: as :func:`reach_bound`.
    """
    points = np.flatnonzero(open_interest)  # (P,)
    num_robots, num_points = len(robot_node), len(points)
    if num_robots == 0 or num_points == 0 or steps <= 0:
        return 0
    # Nodes: 0 source, 1 sink, 2.. points, then robot r at distance j >= 1 (r * steps + j - 1).
    first_level = 2 + num_points
    tails, heads, capacities = [], [], []
    for start in range(0, num_robots, _CHUNK):
        hops = dijkstra(
            adjacency, indices=robot_node[start : start + _CHUNK], unweighted=True, limit=steps
        )[:, points]  # (chunk, P)
        robot, point = np.nonzero((hops >= 1) & (hops <= steps))  # a robot's own waypoint: visited
        level = hops[robot, point].astype(np.int64)
        tails.append(2 + point)
        heads.append(first_level + (start + robot) * steps + level - 1)
        capacities.append(np.ones(len(point), dtype=np.int64))
    tails.append(np.zeros(num_points, dtype=np.int64))  # source -> each point, once
    heads.append(2 + np.arange(num_points))
    capacities.append(np.ones(num_points, dtype=np.int64))
    robot = np.repeat(np.arange(num_robots), steps - 1)
    level = np.tile(np.arange(2, steps + 1), num_robots)  # (R * (steps - 1),)
    tails.append(first_level + robot * steps + level - 1)  # j hops or more -> j - 1 or more
    heads.append(first_level + robot * steps + level - 2)
    capacities.append(steps - level + 1)
    tails.append(first_level + np.arange(num_robots) * steps)  # 1 hop or more -> sink
    heads.append(np.ones(num_robots, dtype=np.int64))
    capacities.append(np.full(num_robots, steps, dtype=np.int64))
    size = first_level + num_robots * steps
    network = sparse.csr_matrix(
        (
            np.concatenate(capacities).astype(np.int32),
            (np.concatenate(tails), np.concatenate(heads)),
        ),
        shape=(size, size),
    )
    return int(maximum_flow(network, 0, 1).flow_value)


def episode_bound(env: Any, seed: int, kind: str = "route") -> int:
    """``kind`` (``"reach"`` or ``"route"``) bound on the reward of the episode of ``seed``.

    Args:
        env: A :class:`~marl_cover.env.CoverageEnv` (reset here with ``seed``).
        seed: The episode's seed.
        kind: Which bound.
    """
    bounds = {"reach": reach_bound, "route": route_bound}
    if kind not in bounds:
        raise ValueError(f"kind must be one of {sorted(bounds)}, got {kind!r}")
    env.reset(seed=seed)
    snapshot = env.snapshot()
    return bounds[kind](
        snapshot.graph.adjacency,
        snapshot.robot_node,
        snapshot.interest & ~snapshot.visited,
        snapshot.max_steps - snapshot.num_steps,
    )
