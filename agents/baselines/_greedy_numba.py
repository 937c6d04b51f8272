"""A compiled kernel for :func:`marl_cover.agents.baselines.greedy.greedy_return` (optional: needs
numba).

It plays the discrete coverage environment on greedy's moves, step for step as
:class:`~marl_cover.env.CoverageEnv` with
:class:`~marl_cover.agents.baselines.greedy.CentralizedGreedyPolicy` (staying when nothing is within
reach) play it, which stays the reference: ``tests/test_greedy.py`` checks that both agree. Greedy's
distances to the points left come from one breadth-first search over the neighbour table, redone
only on the steps that visit a point; collisions are resolved by the rule of
:func:`marl_cover.collisions.resolve_collisions`. A play-out of a rollout's world (a hundred
waypoints, ten robots, twenty steps) costs tens of microseconds instead of several milliseconds.
"""

from __future__ import annotations

import numba
import numpy as np

_FAR = np.iinfo(np.int64).max  # no point left within greedy's reach


@numba.njit(cache=True, nogil=True)
def _distances(neighbors: np.ndarray, left: np.ndarray, limit: int, out: np.ndarray) -> None:
    """Hop distance from every waypoint to the nearest point left, ``_FAR`` beyond ``limit``."""
    queue = np.empty(len(left), dtype=np.int64)
    head, tail = 0, 0
    for v in range(len(left)):
        out[v] = _FAR
        if left[v]:
            out[v] = 0
            queue[tail] = v
            tail += 1
    while head < tail:
        v = queue[head]
        head += 1
        if out[v] >= limit:
            continue
        for slot in range(4):
            u = neighbors[v, slot]
            if u >= 0 and out[u] == _FAR:
                out[u] = out[v] + 1
                queue[tail] = u
                tail += 1


@numba.njit(cache=True, nogil=True)
def _greedy_target(neighbors: np.ndarray, distance: np.ndarray, node: int) -> int:
    """Greedy's next waypoint from ``node``: the neighbour nearest to a point left (the lowest
    slot among equals), or ``node`` itself when none is within reach."""
    best, target = _FAR, node
    for slot in range(4):
        u = neighbors[node, slot]
        if u >= 0 and distance[u] < best:
            best, target = distance[u], u
    return target


@numba.njit(cache=True, nogil=True)
def _resolve(current: np.ndarray, targets: np.ndarray, allow_swaps: bool) -> np.ndarray:
    """:func:`marl_cover.collisions.resolve_collisions` for a handful of robots."""
    num_robots = len(current)
    moving = targets != current
    occupant = np.full(num_robots, -1, dtype=np.int64)
    for i in range(num_robots):
        for j in range(num_robots):
            if current[j] == targets[i]:
                occupant[i] = j
        if moving[i]:  # only the lowest-index mover may claim a waypoint
            for j in range(i):
                if targets[j] != current[j] and targets[j] == targets[i]:
                    moving[i] = False
                    break
    if not allow_swaps:
        for i in range(num_robots):
            k = occupant[i]
            if moving[i] and k >= 0 and targets[k] == current[i]:
                moving[i] = False
    blocked = True
    while blocked:  # a mover into an occupied waypoint goes only if its occupant goes
        blocked = False
        for i in range(num_robots):
            k = occupant[i]
            if moving[i] and k >= 0 and not moving[k]:
                moving[i] = False
                blocked = True
    return np.where(moving, targets, current)


@numba.njit(cache=True, nogil=True)
def greedy_play_out(  # noqa: PLR0913 (one flat kernel)
    neighbors: np.ndarray,
    robot_node: np.ndarray,
    left: np.ndarray,
    steps: int,
    hops: int,
    allow_swaps: bool,
    first: np.ndarray,
) -> int:
    """Points visited in ``steps`` steps of greedy from robots on ``robot_node`` ``(R,)`` with
    the points ``left`` ``(N,)`` unvisited; ``first`` ``(R,)``: each robot's first action
    (``-1``: greedy's; a masked one is a stay)."""
    node = robot_node.copy()
    left = left.copy()
    distance = np.empty(len(left), dtype=np.int64)
    _distances(neighbors, left, hops - 1, distance)
    num_left = int(left.sum())
    targets = np.empty_like(node)
    total = 0
    for step in range(steps):
        if num_left == 0:  # everything covered: the episode has ended
            break
        for i in range(len(node)):
            if step == 0 and first[i] >= 0:
                move = node[i] if first[i] == 0 else neighbors[node[i], first[i] - 1]
                targets[i] = node[i] if move < 0 else move
            else:
                targets[i] = _greedy_target(neighbors, distance, node[i])
        node = _resolve(node, targets, allow_swaps)
        visited = 0
        for i in range(len(node)):
            if left[node[i]]:
                left[node[i]] = False
                visited += 1
        if visited:
            total += visited
            num_left -= visited
            _distances(neighbors, left, hops - 1, distance)
    return total
