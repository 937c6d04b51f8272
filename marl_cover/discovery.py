"""Exploration: the part of the map the team has discovered, kept up to date step by step.

In the exploration task a waypoint becomes known when it lies within ``sensor_range`` metres
(Euclidean, measured from a robot's waypoint, that waypoint included) of a robot, at reset or
after any step. Knowledge is shared by the team and never lost. The team knows:

- the discovered waypoints, their positions and whether each is an unvisited point of interest;
- every lattice edge between two discovered waypoints (the *known graph*);
- which discovered waypoints have an undiscovered neighbour: the **frontier**.

A robot's waypoint and its neighbours (5 m away) are always discovered, so every move a robot
can make is known. :class:`Discovery` updates all of this incrementally: a step touches only the
newly discovered waypoints and their neighbours, and the known edges grow append-only in
discovery order (the order of ``state()`` in exploration). Functions of the whole discovered set
(:func:`known_neighbors`, :func:`frontier_of`) rebuild the same things from scratch, for
recorded episodes and for checks.

Deviations from the paper's code (Tolstaya et al.'s published code): a robot discovers
its own waypoint (the paper's test was ``0 < dist <= 22``, harmless there only because a robot's
start was discovered by another robot or never observed), and undiscovered waypoints and their
edges are absent from observations, not zero rows with half-masked edges (the paper's phantom
edges in batches).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree

from marl_cover.graph import NUM_SLOTS, SpatialGraph

#: Slot of the reverse edge: east <-> west, north <-> south.
OPPOSITE_SLOT = np.array([2, 3, 0, 1])


def sensor_footprints(graph: SpatialGraph, sensor_range: float) -> csr_matrix:
    """Which waypoints a robot on each waypoint senses, ``(N, N)`` CSR: row ``i`` lists the
    waypoints within ``sensor_range`` metres of waypoint ``i`` (``i`` included), sorted."""
    tree = cKDTree(graph.positions)
    pairs = tree.query_pairs(sensor_range, output_type="ndarray")  # (P, 2), i < j
    n = graph.num_nodes
    rows = np.concatenate([pairs[:, 0], pairs[:, 1], np.arange(n)])
    cols = np.concatenate([pairs[:, 1], pairs[:, 0], np.arange(n)])
    footprint = csr_matrix((np.ones(len(rows), dtype=bool), (rows, cols)), shape=(n, n))
    footprint.sort_indices()
    return footprint


def sensed(footprint: csr_matrix, robot_node: np.ndarray) -> np.ndarray:
    """Waypoints sensed by robots on ``robot_node`` ``(R,)``, sorted and unique."""
    return np.unique(sensed_with_repeats(footprint, robot_node))


def sensed_with_repeats(footprint: csr_matrix, robot_node: np.ndarray) -> np.ndarray:
    """The rows of ``footprint`` of every robot, concatenated (a waypoint sensed by several
    robots appears as often), gathered without a loop over robots."""
    starts, ends = footprint.indptr[robot_node], footprint.indptr[robot_node + 1]
    counts = ends - starts  # (R,)
    if counts.sum() == 0:
        return np.zeros(0, dtype=np.int64)
    first = np.repeat(starts - np.cumsum(counts) + counts, counts)  # (S,) row start - offset
    return footprint.indices[first + np.arange(counts.sum())].astype(np.int64, copy=False)


def known_neighbors(graph: SpatialGraph, discovered: np.ndarray) -> np.ndarray:
    """The neighbour table of the known graph, ``(N, 4)`` int64: slots whose waypoint or
    neighbour is undiscovered become ``-1``."""
    nbr = graph.neighbors
    keep = (nbr >= 0) & discovered[nbr.clip(min=0)] & discovered[:, None]
    return np.where(keep, nbr, -1)


def frontier_of(graph: SpatialGraph, discovered: np.ndarray) -> np.ndarray:
    """Discovered waypoints with at least one undiscovered neighbour, ``(N,)`` bool."""
    return frontier_of_rows(graph, discovered, np.arange(graph.num_nodes))


def discovery_steps(footprint: csr_matrix, robot_node: np.ndarray) -> np.ndarray:
    """When each waypoint was discovered in a recorded episode, ``(N,)`` int64.

    Args:
        footprint: :func:`sensor_footprints` of the episode's map.
        robot_node: ``(T + 1, R)`` robot waypoints at reset and after each step.

    Returns:
        The first index ``t`` of ``robot_node`` whose robots sensed the waypoint (0: at reset);
        ``T + 1`` for waypoints never discovered. The discovered set before action ``t`` is
        ``discovery_steps(...) <= t``.
    """
    num_rows = len(robot_node)
    first = np.full(footprint.shape[0], num_rows, dtype=np.int64)
    for t in range(num_rows - 1, -1, -1):  # later rows first, so earlier ones overwrite
        first[sensed(footprint, robot_node[t])] = t
    return first


class Discovery:
    """What the team has discovered of one map; updated in place as robots sense.

    Args:
        graph: The true map.
        footprint: :func:`sensor_footprints` of ``graph``.

    Attributes:
        discovered: ``(N,)`` bool, waypoints known to the team.
        frontier: ``(N,)`` bool, discovered waypoints with an undiscovered neighbour.
        neighbors: ``(N, 4)`` int64, the known graph's neighbour table (same slots as
            ``graph.neighbors``; ``-1`` where the edge is not known).
        order: ``(num_discovered,)`` the discovered waypoints in discovery order (ties: by
            index); a waypoint's position in it is its ``rank``.
        rank: ``(N,)`` int64, position of each waypoint in ``order``, ``-1`` if undiscovered.
        edge_index: ``(2, num_known_edges)`` known directed edges in ranks, in the order they
            became known.
        edge_length: ``(num_known_edges,)`` float32, their lengths in cells.
    """

    def __init__(self, graph: SpatialGraph, footprint: csr_matrix) -> None:
        n = graph.num_nodes
        self.graph = graph
        self.footprint = footprint
        self.discovered = np.zeros(n, dtype=bool)
        self.frontier = np.zeros(n, dtype=bool)
        self.neighbors = np.full((n, NUM_SLOTS), -1, dtype=np.int64)
        self.rank = np.full(n, -1, dtype=np.int64)
        self._order = np.empty(n, dtype=np.int64)
        self._edges = np.empty((2, graph.num_edges), dtype=np.int64)
        self._lengths = np.empty(graph.num_edges, dtype=np.float32)
        self.num_discovered = 0
        self.num_known_edges = 0

    @property
    def order(self) -> np.ndarray:
        """``(num_discovered,)`` the discovered waypoints in discovery order (class docstring)."""
        return self._order[: self.num_discovered]

    @property
    def edge_index(self) -> np.ndarray:
        """``(2, num_known_edges)`` known directed edges in ranks, in the order they were found."""
        return self._edges[:, : self.num_known_edges]

    @property
    def edge_length(self) -> np.ndarray:
        """``(num_known_edges,)`` float32, the known edges' lengths in cells."""
        return self._lengths[: self.num_known_edges]

    def sense(self, robot_node: np.ndarray) -> np.ndarray:
        """Discovers what robots on ``robot_node`` ``(R,)`` sense.

        Returns:
            ``(C,)`` the waypoints whose features changed: the newly discovered ones and the
            old ones that left the frontier (sorted, unique).
        """
        seen = sensed_with_repeats(self.footprint, robot_node)
        new = np.unique(seen[~self.discovered[seen]])  # most of what robots sense is known
        if len(new) == 0:
            return new
        graph = self.graph
        first_new = self.num_discovered  # rank of the first new waypoint
        self.discovered[new] = True
        self.rank[new] = self.num_discovered + np.arange(len(new))
        self._order[self.num_discovered : self.num_discovered + len(new)] = new
        self.num_discovered += len(new)

        nbr = graph.neighbors[new]  # (C, 4)
        known = (nbr >= 0) & self.discovered[nbr.clip(min=0)]  # edges that became known
        rows, slots = np.nonzero(known)
        v, u = new[rows], nbr[rows, slots]
        self.neighbors[v, slots] = u
        self.neighbors[u, OPPOSITE_SLOT[slots]] = v
        # v -> u for every new edge; u -> v too unless u is new (its own row adds it)
        back = self.rank[u] < first_new
        senders = np.concatenate([v, u[back]])
        receivers = np.concatenate([u, v[back]])
        length = graph.neighbor_distances[v, slots]
        lengths = np.concatenate([length, length[back]])
        k = self.num_known_edges
        self._edges[0, k : k + len(senders)] = self.rank[senders]
        self._edges[1, k : k + len(senders)] = self.rank[receivers]
        self._lengths[k : k + len(senders)] = lengths
        self.num_known_edges += len(senders)

        touched = np.union1d(new, u)
        self.frontier[touched] = frontier_of_rows(graph, self.discovered, touched)
        return touched


def frontier_of_rows(graph: SpatialGraph, discovered: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """:func:`frontier_of` for the waypoints ``rows`` only, ``(len(rows),)`` bool."""
    nbr = graph.neighbors[rows]
    hidden = (nbr >= 0) & ~discovered[nbr.clip(min=0)]
    return discovered[rows] & hidden.any(axis=1)
