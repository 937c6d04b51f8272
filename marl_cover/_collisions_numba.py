"""A compiled :func:`marl_cover.collisions.resolve_collisions` (optional: needs numba).

The same rule in time linear in the team: who stands on each waypoint and who claims it come
from two ``(N,)`` tables (:class:`marl_cover.ego.EgoScratch`, restored to ``-1`` after the call),
and blocks spread along chains from the robots that stay, through the claimer of each one's
waypoint, instead of sweeps over the team until nothing changes. The numpy function stays the
reference; ``tests/test_collisions.py`` runs its cases and its property test on both.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def resolve_compiled(
    current: np.ndarray,  # (R,) int64, pairwise distinct
    targets: np.ndarray,  # (R,) int64
    allow_swaps: bool,
    robot_at: np.ndarray,  # (N,) -1: robot on each waypoint
    claim: np.ndarray,  # (N,) -1: the mover that claims each waypoint
    next_node: np.ndarray,  # (R,) int64, out
) -> int:
    """Writes each robot's next waypoint; returns -1, or the first robot whose current
    waypoint another robot already holds (nothing is written then)."""
    num_robots = current.shape[0]
    shared = -1
    for j in range(num_robots):
        if robot_at[current[j]] >= 0:
            shared = j
            break
        robot_at[current[j]] = j
    moving = np.zeros(num_robots, np.bool_)
    stack = np.empty(num_robots, np.int64)
    top = 0
    if shared < 0:
        for i in range(num_robots):  # the lowest-index mover claims a waypoint
            t = targets[i]
            if t != current[i] and claim[t] < 0:
                claim[t] = i
                moving[i] = True
        if not allow_swaps:
            for i in range(num_robots):
                k = robot_at[targets[i]]
                if moving[i] and k >= 0 and targets[k] == current[i]:
                    moving[i] = False
        for k in range(num_robots):
            if not moving[k]:
                stack[top] = k
                top += 1
        while top > 0:  # a robot that stays blocks the mover into its waypoint, and so on
            top -= 1
            i = claim[current[stack[top]]]
            if i >= 0 and moving[i]:
                moving[i] = False
                stack[top] = i
                top += 1
        for i in range(num_robots):
            next_node[i] = targets[i] if moving[i] else current[i]
    for i in range(num_robots):
        claim[targets[i]] = -1
    for j in range(num_robots):
        if robot_at[current[j]] == j:
            robot_at[current[j]] = -1
    return shared
