"""Priority-index collision resolution for simultaneous moves on a graph.

The rule (paper, Sec. "Implementation Details", made airtight): a robot moves to its target
waypoint only if no other robot occupies that waypoint at the next step. Among robots that
target the same waypoint the lowest index wins and the others stay. A robot that stays keeps
its waypoint, so a robot moving into it is blocked too, and blocks cascade along chains. Chains
(A follows B who follows C) and cycles of three or more robots move together when their head is
free; two robots swapping along one edge is allowed unless ``allow_swaps=False``.

Invariant: the returned positions are pairwise distinct whenever the current ones are.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from marl_cover.ego import EgoScratch


def resolve_collisions(
    current: np.ndarray, targets: np.ndarray, allow_swaps: bool = True
) -> np.ndarray:
    """Next waypoint of each robot after resolving conflicts.

    Args:
        current: Waypoint of each robot now, ``(num_robots,)`` int, pairwise distinct.
        targets: Waypoint each robot wants to move to, ``(num_robots,)`` int (its own waypoint
            to stay).
        allow_swaps: Whether two robots may exchange waypoints along one edge.

    Returns:
        Waypoint of each robot at the next step, ``(num_robots,)`` int64.

    Raises:
        ValueError: shapes differ or two robots share a current waypoint.
    """
    current = np.asarray(current, dtype=np.int64)
    targets = np.asarray(targets, dtype=np.int64)
    if current.shape != targets.shape or current.ndim != 1:
        raise ValueError(
            f"current and targets must be equal-length 1-D arrays, got {current.shape} "
            f"and {targets.shape}"
        )
    num_robots = len(current)
    order = np.argsort(current, kind="stable")
    sorted_current = current[order]
    if num_robots > 1 and (sorted_current[1:] == sorted_current[:-1]).any():
        dup = sorted_current[1:][sorted_current[1:] == sorted_current[:-1]][0]
        raise ValueError(f"two robots share waypoint {dup}: {np.flatnonzero(current == dup)}")

    moving = targets != current
    # Only the lowest-index mover may claim a waypoint; np.unique reports first occurrences.
    mover_ids = np.flatnonzero(moving)
    _, first = np.unique(targets[mover_ids], return_index=True)
    winners = np.zeros(num_robots, dtype=bool)
    winners[mover_ids[first]] = True
    moving &= winners

    # Occupant of each target now (-1 if free), via a search in the sorted current positions.
    pos = np.searchsorted(sorted_current, targets).clip(max=max(num_robots - 1, 0))
    occupant = np.where(sorted_current[pos] == targets, order[pos], -1)
    has_occupant = occupant >= 0
    if not allow_swaps:
        swap = moving & has_occupant
        swap[swap] = targets[occupant[swap]] == current[swap]
        moving &= ~swap
    # A mover into an occupied waypoint goes only if its occupant goes: iterate to a fixpoint.
    while True:
        blocked = moving & has_occupant
        blocked[blocked] = ~moving[occupant[blocked]]
        if not blocked.any():
            break
        moving &= ~blocked
    return np.where(moving, targets, current)


def resolve_collisions_compiled(
    current: np.ndarray, targets: np.ndarray, allow_swaps: bool, scratch: EgoScratch
) -> np.ndarray:
    """:func:`resolve_collisions` in a compiled kernel, linear in the team (needs numba):
    ``scratch`` holds the map's occupancy and claim tables (:class:`marl_cover.ego.EgoScratch`).

    Raises:
        ValueError: two robots share a current waypoint.
    """
    from marl_cover._collisions_numba import resolve_compiled

    current = np.ascontiguousarray(current, dtype=np.int64)
    targets = np.ascontiguousarray(targets, dtype=np.int64)
    next_node = np.empty(len(current), dtype=np.int64)
    shared = resolve_compiled(
        current, targets, allow_swaps, scratch.robot_at, scratch.claim, next_node
    )
    if shared >= 0:
        dup = current[shared]
        raise ValueError(f"two robots share waypoint {dup}: {np.flatnonzero(current == dup)}")
    return next_node
