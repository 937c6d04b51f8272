"""Compiled kernels for :mod:`marl_cover.ego` (optional: need numba).

:func:`fill_ego_graphs` fills the same padded arrays, in the same order, as the numpy
implementation, which stays the reference (``tests/test_ego.py`` checks that both agree);
:func:`fill_compact` writes the same ego-graphs without padding, one after the other, into
step-wide tables (:mod:`marl_cover.compact`).

Each robot's ego-graph costs one breadth-first search over the neighbour table, bounded by its
ball, and the other robots in it are read from an occupancy table (the robot on each
waypoint), so the work is linear in the team size and independent of the map's size: the
search state (:class:`marl_cover.ego.EgoScratch`) is kept between calls and restored after
each robot.
"""

from __future__ import annotations

import numba
import numpy as np

_ACTIONS = 5
_EGO_EDGES = 2 * _ACTIONS
#: Status codes of the kernels.
OK, TOO_MANY_NODES, TOO_MANY_EDGES = 0, -1, -2


@numba.njit(cache=True, nogil=True)
def _slot_target(neighbors: np.ndarray, node: int, slot: int) -> int:
    return node if slot == 0 else neighbors[node, slot - 1]


@numba.njit(cache=True, nogil=True)
def _slot_length(lengths: np.ndarray, node: int, slot: int) -> float:
    return 0.0 if slot == 0 else lengths[node, slot - 1]


@numba.njit(cache=True, nogil=True)
def _ball(
    neighbors: np.ndarray,
    start: int,
    hops: int,
    dist: np.ndarray,
    queue: np.ndarray,
    ball: np.ndarray,
    row_of: np.ndarray,
    row_lo: np.ndarray,
    row_hi: np.ndarray,
) -> int:
    """Breadth-first search to ``hops`` hops of ``start``: sets ``dist`` of the ball's waypoints
    and writes them to ``ball[:size]`` in increasing index; returns ``size``.

    With a row table (``row_of``, see :class:`marl_cover.ego.EgoScratch`; empty otherwise) the
    ball is read in index order row by row, from the lowest to the highest index the search met
    on each of its ``2 hops + 1`` rows (``row_lo``, ``row_hi``); without, it is sorted.
    """
    rows = row_of.shape[0] > 0
    if rows:
        row_lo[:] = dist.shape[0]
        row_hi[:] = -1
        base = row_of[start] - hops
    dist[start] = 0
    queue[0] = start
    head, tail = 0, 1
    while head < tail:
        u = queue[head]
        head += 1
        if rows:
            r = row_of[u] - base
            row_lo[r] = min(row_lo[r], u)
            row_hi[r] = max(row_hi[r], u)
        if dist[u] >= hops:
            continue
        for s in range(4):
            v = neighbors[u, s]
            if v >= 0 and dist[v] < 0:
                dist[v] = dist[u] + 1
                queue[tail] = v
                tail += 1
    if not rows:
        ball[:tail] = queue[:tail]
        ball[:tail].sort()
        return tail
    size = 0
    for r in range(row_lo.shape[0]):
        for u in range(row_lo[r], row_hi[r] + 1):
            if dist[u] >= 0:
                ball[size] = u
                size += 1
    return size


@numba.njit(cache=True, nogil=True)
def _others(
    ball: np.ndarray,
    robot_at: np.ndarray,
    next_robot: np.ndarray,
    ego: int,
    hops: int,
    out: np.ndarray,
) -> int:
    """The robots other than ``ego`` standing on the waypoints ``ball``, in robot order, into
    ``out``; returns their count (none below two hops: robot -> waypoint -> robot)."""
    count = 0
    if hops < 2:
        return 0
    for k in range(ball.shape[0]):
        j = robot_at[ball[k]]
        while j >= 0:
            if j != ego:
                out[count] = j
                count += 1
            j = next_robot[j]
    out[:count].sort()
    return count


@numba.njit(cache=True, nogil=True)
def _place(robot_node: np.ndarray, robot_at: np.ndarray, next_robot: np.ndarray) -> None:
    """Writes the occupancy table: ``robot_at`` holds the first robot on each waypoint and
    ``next_robot`` chains the others on it (a view may show two robots on one waypoint)."""
    for j in range(robot_node.shape[0] - 1, -1, -1):
        next_robot[j] = robot_at[robot_node[j]]
        robot_at[robot_node[j]] = j


@numba.njit(cache=True, nogil=True)
def _clear(robot_node: np.ndarray, robot_at: np.ndarray) -> None:
    """Restores the occupancy table to ``-1``."""
    for j in range(robot_node.shape[0]):
        robot_at[robot_node[j]] = -1


@numba.njit(cache=True, nogil=True)
def fill_ego_graphs(  # noqa: PLR0913, PLR0912, PLR0915 (one flat kernel)
    neighbors: np.ndarray,  # (N, 4) int64
    lengths: np.ndarray,  # (N, 4) float32
    cells: np.ndarray,  # (N, 2) float32
    features: np.ndarray,  # (N, 4) float32
    robot_node: np.ndarray,  # (R,) int64
    hops: int,
    dist: np.ndarray,  # marl_cover.ego.EgoScratch
    queue: np.ndarray,
    ball_buffer: np.ndarray,
    robot_at: np.ndarray,
    row_of: np.ndarray,
    nodes: np.ndarray,  # (R, M, 4) float32, zeros
    node_pos: np.ndarray,  # (R, M, 2) float32, zeros
    node_mask: np.ndarray,  # (R, M) bool, False
    edge_index: np.ndarray,  # (R, 2, E) int64, sink
    edge_attr: np.ndarray,  # (R, E, 1) float32, zeros
    edge_mask: np.ndarray,  # (R, E) bool, False
    action_mask: np.ndarray,  # (R, 5) int8, zeros
    used: np.ndarray,  # (R, 2) int64, out: nodes and edge slots written, per robot
) -> int:
    """Fills the pre-initialised padded arrays (as :func:`clear_padded` leaves them); records
    the extent written in ``used``; returns ``OK`` or a status of too many nodes or edges."""
    num_robots = robot_node.shape[0]
    sink = nodes.shape[1] - 1
    max_edges = edge_attr.shape[1]
    others = np.empty(num_robots, np.int64)
    next_robot = np.empty(num_robots, np.int64)
    row_lo = np.empty(2 * hops + 1, np.int64)
    row_hi = np.empty(2 * hops + 1, np.int64)
    _place(robot_node, robot_at, next_robot)
    status = OK
    for i in range(num_robots):
        p = robot_node[i]
        tail = _ball(neighbors, p, hops, dist, queue, ball_buffer, row_of, row_lo, row_hi)
        ball = ball_buffer[:tail]
        num_others = _others(ball, robot_at, next_robot, i, hops, others)
        count = 1 + tail + num_others
        if count > sink:
            status = TOO_MANY_NODES
        else:
            nodes[i, 0, 0] = 1.0
            for k in range(tail):
                w = ball[k]
                dist[w] = k + 1  # from here on, dist holds the local id
                for f in range(4):
                    nodes[i, k + 1, f] = features[w, f]
                node_pos[i, k + 1, 0] = cells[w, 0] - cells[p, 0]
                node_pos[i, k + 1, 1] = cells[w, 1] - cells[p, 1]
            for k in range(num_others):
                q = robot_node[others[k]]
                nodes[i, 1 + tail + k, 0] = 1.0
                node_pos[i, 1 + tail + k, 0] = cells[q, 0] - cells[p, 0]
                node_pos[i, 1 + tail + k, 1] = cells[q, 1] - cells[p, 1]
            for k in range(count):
                node_mask[i, k] = True
            for k in range(_ACTIONS):
                t = _slot_target(neighbors, p, k)
                if t >= 0:
                    length = _slot_length(lengths, p, k)
                    action_mask[i, k] = 1
                    edge_index[i, 0, k] = dist[t]
                    edge_index[i, 1, k] = 0
                    edge_index[i, 0, _ACTIONS + k] = 0
                    edge_index[i, 1, _ACTIONS + k] = dist[t]
                    edge_attr[i, k, 0] = length
                    edge_attr[i, _ACTIONS + k, 0] = length
                    edge_mask[i, k] = True
                    edge_mask[i, _ACTIONS + k] = True
            c = _EGO_EDGES
            for k in range(tail):
                u = ball[k]
                for s in range(4):
                    v = neighbors[u, s]
                    if v >= 0 and dist[v] >= 0:
                        if c >= max_edges:
                            status = TOO_MANY_EDGES
                            break
                        edge_index[i, 0, c] = k + 1
                        edge_index[i, 1, c] = dist[v]
                        edge_attr[i, c, 0] = lengths[u, s]
                        edge_mask[i, c] = True
                        c += 1
            for k in range(num_others):
                q = robot_node[others[k]]
                rl = 1 + tail + k  # the robot's local id
                for slot in range(_ACTIONS):
                    t = _slot_target(neighbors, q, slot)
                    if t >= 0 and dist[t] >= 0:
                        if c + 1 >= max_edges:
                            status = TOO_MANY_EDGES
                            break
                        length = _slot_length(lengths, q, slot)
                        edge_index[i, 0, c] = dist[t]
                        edge_index[i, 1, c] = rl
                        edge_index[i, 0, c + 1] = rl
                        edge_index[i, 1, c + 1] = dist[t]
                        edge_attr[i, c, 0] = length
                        edge_attr[i, c + 1, 0] = length
                        edge_mask[i, c] = True
                        edge_mask[i, c + 1] = True
                        c += 2
            used[i, 0] = count
            used[i, 1] = c
        for k in range(tail):
            dist[ball[k]] = -1
        if status != OK:
            break
    _clear(robot_node, robot_at)
    return status


@numba.njit(cache=True, nogil=True)
def fill_compact(  # noqa: PLR0913, PLR0912, PLR0915 (one flat kernel)
    neighbors: np.ndarray,  # (N, 4) int64
    lengths: np.ndarray,  # (N, 4) float32
    cells: np.ndarray,  # (N, 2) float32
    features: np.ndarray,  # (N, 4) float32
    robot_node: np.ndarray,  # (R,) int64
    hops: int,
    dist: np.ndarray,  # marl_cover.ego.EgoScratch
    queue: np.ndarray,
    ball_buffer: np.ndarray,
    robot_at: np.ndarray,
    row_of: np.ndarray,
    node_offsets: np.ndarray,  # (R + 1,) int64, out
    nodes: np.ndarray,  # (capacity_nodes, 6) float32, out
    edge_offsets: np.ndarray,  # (R + 1,) int64, out
    edge_links: np.ndarray,  # (capacity_edges, 2) int32, out
    edge_attr: np.ndarray,  # (capacity_edges, 1) float32, out
    action_mask: np.ndarray,  # (R, 5) int8, out
) -> int:
    """Writes every robot's ego-graph, unpadded, one after the other (the layout of
    :class:`marl_cover.compact.CompactObservations`); returns ``OK`` or a status of too many
    nodes or edges for the tables' capacity (the caller retries with larger tables)."""
    num_robots = robot_node.shape[0]
    node_capacity = nodes.shape[0]
    edge_capacity = edge_attr.shape[0]
    others = np.empty(num_robots, np.int64)
    next_robot = np.empty(num_robots, np.int64)
    row_lo = np.empty(2 * hops + 1, np.int64)
    row_hi = np.empty(2 * hops + 1, np.int64)
    _place(robot_node, robot_at, next_robot)
    status = OK
    n0, e0 = 0, 0
    node_offsets[0], edge_offsets[0] = 0, 0
    for i in range(num_robots):
        p = robot_node[i]
        tail = _ball(neighbors, p, hops, dist, queue, ball_buffer, row_of, row_lo, row_hi)
        ball = ball_buffer[:tail]
        num_others = _others(ball, robot_at, next_robot, i, hops, others)
        count = 1 + tail + num_others
        if n0 + count > node_capacity:
            status = TOO_MANY_NODES
        else:
            px, py = cells[p, 0], cells[p, 1]
            nodes[n0, 0] = 1.0
            for f in range(1, 6):
                nodes[n0, f] = 0.0
            for k in range(tail):
                w = ball[k]
                dist[w] = k + 1  # from here on, dist holds the local id
                row = n0 + k + 1
                for f in range(4):
                    nodes[row, f] = features[w, f]
                nodes[row, 4] = cells[w, 0] - px
                nodes[row, 5] = cells[w, 1] - py
            for k in range(num_others):
                q = robot_node[others[k]]
                row = n0 + 1 + tail + k
                nodes[row, 0] = 1.0
                nodes[row, 1] = 0.0
                nodes[row, 2] = 0.0
                nodes[row, 3] = 0.0
                nodes[row, 4] = cells[q, 0] - px
                nodes[row, 5] = cells[q, 1] - py
            num_actions = 0
            for k in range(_ACTIONS):
                action_mask[i, k] = 1 if _slot_target(neighbors, p, k) >= 0 else 0
                num_actions += action_mask[i, k]
            c = e0
            if c + 2 * num_actions > edge_capacity:
                status = TOO_MANY_EDGES
            else:
                for k in range(_ACTIONS):  # action edges: in (target -> ego), then out
                    t = _slot_target(neighbors, p, k)
                    if t >= 0:
                        length = _slot_length(lengths, p, k)
                        edge_links[c, 0] = dist[t]
                        edge_links[c, 1] = 0
                        edge_links[c + num_actions, 0] = 0
                        edge_links[c + num_actions, 1] = dist[t]
                        edge_attr[c, 0] = length
                        edge_attr[c + num_actions, 0] = length
                        c += 1
                c += num_actions
            for k in range(tail):
                if status != OK:
                    break
                u = ball[k]
                for s in range(4):
                    v = neighbors[u, s]
                    if v >= 0 and dist[v] >= 0:
                        if c >= edge_capacity:
                            status = TOO_MANY_EDGES
                            break
                        edge_links[c, 0] = k + 1
                        edge_links[c, 1] = dist[v]
                        edge_attr[c, 0] = lengths[u, s]
                        c += 1
            for k in range(num_others):
                if status != OK:
                    break
                q = robot_node[others[k]]
                rl = 1 + tail + k
                for slot in range(_ACTIONS):
                    t = _slot_target(neighbors, q, slot)
                    if t >= 0 and dist[t] >= 0:
                        if c + 2 > edge_capacity:
                            status = TOO_MANY_EDGES
                            break
                        length = _slot_length(lengths, q, slot)
                        edge_links[c, 0] = dist[t]
                        edge_links[c, 1] = rl
                        edge_links[c + 1, 0] = rl
                        edge_links[c + 1, 1] = dist[t]
                        edge_attr[c, 0] = length
                        edge_attr[c + 1, 0] = length
                        c += 2
            n0 += count
            e0 = c
            node_offsets[i + 1] = n0
            edge_offsets[i + 1] = e0
        for k in range(tail):
            dist[ball[k]] = -1
        if status != OK:
            break
    _clear(robot_node, robot_at)
    return status


@numba.njit(cache=True, nogil=True)
def clear_padded(
    nodes: np.ndarray,
    node_pos: np.ndarray,
    node_mask: np.ndarray,
    edge_index: np.ndarray,
    edge_attr: np.ndarray,
    edge_mask: np.ndarray,
    action_mask: np.ndarray,
    used: np.ndarray,  # (R, 2) int64: what the last fill wrote, per robot
) -> None:
    """Returns padded arrays to their initial state (zeros, the sink, ``False``) where the last
    :func:`fill_ego_graphs` wrote, so that a set of arrays can be filled again without
    initialising all of it."""
    sink = nodes.shape[1] - 1
    for i in range(used.shape[0]):
        for k in range(used[i, 0]):
            for f in range(nodes.shape[2]):
                nodes[i, k, f] = 0.0
            node_pos[i, k, 0] = 0.0
            node_pos[i, k, 1] = 0.0
            node_mask[i, k] = False
        for k in range(used[i, 1]):
            edge_index[i, 0, k] = sink
            edge_index[i, 1, k] = sink
            edge_attr[i, k, 0] = 0.0
            edge_mask[i, k] = False
        for k in range(action_mask.shape[1]):
            action_mask[i, k] = 0
