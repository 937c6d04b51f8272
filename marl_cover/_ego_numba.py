"""A compiled kernel for :func:`marl_cover.ego.build_ego_graphs` (optional: needs numba).

It fills the same arrays, in the same order, as the numpy implementation, which stays the
reference (``tests/test_ego.py`` checks that both agree). One breadth-first search per robot
over the neighbour table replaces the batched ``dijkstra`` and the dense ``(R, N)`` masks; on
these machines the whole observation build becomes several times faster (see
``scripts/bench_env.py``).
"""

from __future__ import annotations

import numba
import numpy as np

_ACTIONS = 5
_EGO_EDGES = 2 * _ACTIONS


@numba.njit(cache=True, nogil=True)
def _slot_target(neighbors: np.ndarray, node: int, slot: int) -> int:
    return node if slot == 0 else neighbors[node, slot - 1]


@numba.njit(cache=True, nogil=True)
def _slot_length(lengths: np.ndarray, node: int, slot: int) -> float:
    return 0.0 if slot == 0 else lengths[node, slot - 1]


@numba.njit(cache=True, nogil=True)
def fill_ego_graphs(  # noqa: PLR0913, PLR0912, PLR0915 (one flat kernel)
    neighbors: np.ndarray,  # (N, 4) int64
    lengths: np.ndarray,  # (N, 4) float32
    cells: np.ndarray,  # (N, 2) float32
    features: np.ndarray,  # (N, 4) float32
    robot_node: np.ndarray,  # (R,) int64
    hops: int,
    nodes: np.ndarray,  # (R, M, 4) float32, zeros
    node_pos: np.ndarray,  # (R, M, 2) float32, zeros
    node_mask: np.ndarray,  # (R, M) bool, False
    edge_index: np.ndarray,  # (R, 2, E) int64, sink
    edge_attr: np.ndarray,  # (R, E, 1) float32, zeros
    edge_mask: np.ndarray,  # (R, E) bool, False
    action_mask: np.ndarray,  # (R, 5) int8, zeros
) -> int:
    """Fills the pre-initialised arrays; returns 0, or -1 (too many nodes) / -2 (edges)."""
    num_nodes = neighbors.shape[0]
    num_robots = robot_node.shape[0]
    sink = nodes.shape[1] - 1
    max_edges = edge_attr.shape[1]
    dist = np.full(num_nodes, -1, np.int64)
    local = np.zeros(num_nodes, np.int64)
    queue = np.empty(num_nodes, np.int64)
    robot_local = np.empty(num_robots, np.int64)
    for i in range(num_robots):
        p = robot_node[i]
        dist[p] = 0
        queue[0] = p
        head, tail = 0, 1
        while head < tail:
            u = queue[head]
            head += 1
            if dist[u] >= hops:
                continue
            for s in range(4):
                v = neighbors[u, s]
                if v >= 0 and dist[v] < 0:
                    dist[v] = dist[u] + 1
                    queue[tail] = v
                    tail += 1
        ball = np.sort(queue[:tail])
        nodes[i, 0, 0] = 1.0
        for k in range(tail):
            w = ball[k]
            local[w] = k + 1
            for f in range(4):
                nodes[i, k + 1, f] = features[w, f]
            node_pos[i, k + 1, 0] = cells[w, 0] - cells[p, 0]
            node_pos[i, k + 1, 1] = cells[w, 1] - cells[p, 1]
        count = tail + 1
        for j in range(num_robots):
            robot_local[j] = -1
            q = robot_node[j]
            if j != i and hops >= 2 and dist[q] >= 0:
                if count >= sink:
                    return -1
                robot_local[j] = count
                nodes[i, count, 0] = 1.0
                node_pos[i, count, 0] = cells[q, 0] - cells[p, 0]
                node_pos[i, count, 1] = cells[q, 1] - cells[p, 1]
                count += 1
        if count > sink:
            return -1
        for k in range(count):
            node_mask[i, k] = True
        for k in range(_ACTIONS):
            t = _slot_target(neighbors, p, k)
            if t >= 0:
                length = _slot_length(lengths, p, k)
                action_mask[i, k] = 1
                edge_index[i, 0, k] = local[t]
                edge_index[i, 1, k] = 0
                edge_index[i, 0, _ACTIONS + k] = 0
                edge_index[i, 1, _ACTIONS + k] = local[t]
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
                        return -2
                    edge_index[i, 0, c] = k + 1
                    edge_index[i, 1, c] = local[v]
                    edge_attr[i, c, 0] = lengths[u, s]
                    edge_mask[i, c] = True
                    c += 1
        for j in range(num_robots):
            if robot_local[j] < 0:
                continue
            q = robot_node[j]
            for k in range(_ACTIONS):
                t = _slot_target(neighbors, q, k)
                if t >= 0 and dist[t] >= 0:
                    if c + 1 >= max_edges:
                        return -2
                    length = _slot_length(lengths, q, k)
                    edge_index[i, 0, c] = local[t]
                    edge_index[i, 1, c] = robot_local[j]
                    edge_index[i, 0, c + 1] = robot_local[j]
                    edge_index[i, 1, c + 1] = local[t]
                    edge_attr[i, c, 0] = length
                    edge_attr[i, c + 1, 0] = length
                    edge_mask[i, c] = True
                    edge_mask[i, c + 1] = True
                    c += 2
        for k in range(tail):
            dist[queue[k]] = -1
    return 0
