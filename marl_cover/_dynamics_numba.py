"""Compiled kernels of the continuous-time mode (optional: needs numba): the bodies
(:meth:`marl_cover.dynamics.QuadrotorTeam.advance`), the lattice lookup of
:class:`marl_cover.locator.WaypointLocator` and the near-miss count.

Each runs the same arithmetic, in the same order, as the numpy implementation, which stays the
reference (``tests/test_dynamics.py`` checks that both give the same bits). A control period of
ten integration steps for a team of ten costs microseconds instead of the ~0.3 ms of numpy
calls, which was most of the simulation's time in the quadrotor mission
(``scripts/bench_mission.py``).
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def _clip_rows(vectors: np.ndarray, limit: float) -> None:
    """``dynamics.clip_norm`` in place: when some row's norm exceeds ``limit``, every row is
    scaled by ``min(1, limit / norm)`` (as the vectorised reference does)."""
    if math.isinf(limit):
        return
    rows = vectors.shape[0]
    squared = np.empty(rows)
    largest = -1.0
    for i in range(rows):
        x, y, z = vectors[i, 0], vectors[i, 1], vectors[i, 2]
        squared[i] = x * x + y * y + z * z
        largest = max(largest, squared[i])
    if largest <= limit * limit:
        return
    for i in range(rows):
        scale = min(1.0, limit / math.sqrt(squared[i] + 1e-300))
        for j in range(3):
            vectors[i, j] = vectors[i, j] * scale


@numba.njit(cache=True, nogil=True)
def advance_team(  # noqa: PLR0913 (one flat kernel)
    position: np.ndarray,  # (R, 3) float64, updated in place
    velocity: np.ndarray,  # (R, 3) float64, updated in place
    acceleration: np.ndarray,  # (R, 3) float64, receives the last command
    acting: np.ndarray,  # (S, R, 3) float64, the target acting at each step
    noise: np.ndarray,  # (S, R, 3) float64 measurement noise, or (0, R, 3) for none
    position_gain: float,
    velocity_gain: float,
    drag_rate: float,
    dt: float,
    max_speed: float,
    max_accel: float,
    track: np.ndarray,  # (S, R, 3) float64, receives the positions after each step
) -> None:
    """Integrates ``S`` steps of the cascaded controller and the body (see ``dynamics``)."""
    steps, rows = acting.shape[0], position.shape[0]
    desired = np.empty((rows, 3))
    command = np.empty((rows, 3))
    for k in range(steps):
        for i in range(rows):
            for j in range(3):
                measured = position[i, j] + noise[k, i, j] if noise.shape[0] else position[i, j]
                desired[i, j] = position_gain * (acting[k, i, j] - measured)
        _clip_rows(desired, max_speed)
        for i in range(rows):
            for j in range(3):
                v = velocity[i, j]
                command[i, j] = velocity_gain * (desired[i, j] - v) + drag_rate * v
        _clip_rows(command, max_accel)
        for i in range(rows):
            for j in range(3):
                v = velocity[i, j] + dt * (command[i, j] - drag_rate * velocity[i, j])
                velocity[i, j] = v
                position[i, j] = position[i, j] + dt * v
                track[k, i, j] = position[i, j]
    acceleration[:] = command


@numba.njit(cache=True, nogil=True)
def lattice_nearest(  # noqa: PLR0913 (one flat kernel)
    xy: np.ndarray,  # (P, >=2) float64, points (their first two coordinates)
    origin: np.ndarray,  # (2,) float64, the lattice's corner
    cell_size: float,
    table: np.ndarray,  # (A, B) int64, waypoint at each lattice point (-1: none)
    positions: np.ndarray,  # (N, 2) float64, the waypoints
    node: np.ndarray,  # (P,) int64, receives the nearest waypoint (-1: not on the lattice)
    distance: np.ndarray,  # (P,) float64, receives the distance to it
) -> int:
    """``WaypointLocator.nearest``'s table lookup; returns how many points round to no
    waypoint (left at ``-1`` for the k-d tree)."""
    missing = 0
    for p in range(xy.shape[0]):
        i = np.int64(np.rint((xy[p, 0] - origin[0]) / cell_size))
        j = np.int64(np.rint((xy[p, 1] - origin[1]) / cell_size))
        found = -1
        if 0 <= i < table.shape[0] and 0 <= j < table.shape[1]:
            found = table[i, j]
        node[p] = found
        if found < 0:
            missing += 1
            continue
        dx, dy = xy[p, 0] - positions[found, 0], xy[p, 1] - positions[found, 1]
        distance[p] = np.sqrt(dx * dx + dy * dy)
    return missing


@numba.njit(cache=True, nogil=True)
def count_new_close_pairs(
    position: np.ndarray,  # (R, 3) float64
    safety_distance: float,
    same_altitude: float,
    close: np.ndarray,  # (R, R) bool, the pairs close at the last check; updated in place
) -> int:
    """Pairs within ``safety_distance`` in the plane and ``same_altitude`` in height that were
    not close at the last check (``QuadrotorCoverageEnv._count_near_misses``)."""
    rows = position.shape[0]
    new = 0
    for i in range(rows):
        for j in range(i + 1, rows):
            dx, dy = position[i, 0] - position[j, 0], position[i, 1] - position[j, 1]
            now = (
                np.sqrt(dx * dx + dy * dy) < safety_distance
                and abs(position[i, 2] - position[j, 2]) < same_altitude
            )
            if now and not close[i, j]:
                new += 1
            close[i, j] = now
            close[j, i] = now
    return new
