"""A compiled kernel for the distances of :func:`marl_cover.agents.models.gnn.receptive_field`
(optional: needs numba).

The torch reference relaxes every edge ``hops - 1`` times (Bellman-Ford, ~3 tensor ops a
round); on the small graphs a robot decides on, those ~90 calls cost more than the search
itself. A breadth-first search from the output edges' endpoints against the edge direction
gives the same capped distances (``tests/test_gnn.py`` checks both).
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def capped_distances(
    senders: np.ndarray,  # (E,) int64
    receivers: np.ndarray,  # (E,) int64
    sources: np.ndarray,  # (S,) int64, distance 0
    num_nodes: int,
    hops: int,
) -> np.ndarray:
    """Hops from each node along the edges to a source, ``hops`` where more than ``hops - 1``
    (or never), ``(num_nodes,)`` int64."""
    num_edges = senders.shape[0]
    start = np.zeros(num_nodes + 1, np.int64)  # edges into each receiver, compressed
    for i in range(num_edges):
        start[receivers[i] + 1] += 1
    for v in range(num_nodes):
        start[v + 1] += start[v]
    fill = start[:-1].copy()
    into = np.empty(num_edges, np.int64)  # senders grouped by receiver
    for i in range(num_edges):
        into[fill[receivers[i]]] = senders[i]
        fill[receivers[i]] += 1
    distance = np.full(num_nodes, hops, np.int64)
    queue = np.empty(num_nodes, np.int64)
    head, tail = 0, 0
    for s in sources:
        if distance[s] != 0:
            distance[s] = 0
            queue[tail] = s
            tail += 1
    while head < tail:
        u = queue[head]
        head += 1
        reach = distance[u] + 1
        if reach > hops - 1:
            continue
        for k in range(start[u], start[u + 1]):
            w = into[k]
            if distance[w] > reach:
                distance[w] = reach
                queue[tail] = w
                tail += 1
    return distance
