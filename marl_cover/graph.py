"""Spatial waypoint graphs: positions in metres, a fixed-slot neighbour table, sparse adjacency.

A :class:`SpatialGraph` is the map the robots move on. Every waypoint has at most one
neighbour in each of four geometric directions, stored in a ``(num_nodes, 4)`` table whose
columns are the *slots* east, north, west, south (``-1`` where there is no neighbour). The
slot order is the order of the move actions 1-4 of the environment, so an action means the
same direction everywhere on the map.

Nothing here builds a dense ``num_nodes x num_nodes`` matrix: adjacency is CSR and hop
distances come from :func:`scipy.sparse.csgraph.dijkstra` restricted to the sources asked for.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components, dijkstra

from marl_cover.errors import as_node_indices, check_finite

#: Names of the four neighbour slots, in action order (action ``k`` moves to slot ``k - 1``).
SLOT_NAMES = ("east", "north", "west", "south")
NUM_SLOTS = 4
#: Unit vectors of the slots, ``(4, 2)``: +x is east, +y is north.
SLOT_DIRECTIONS = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])


@dataclass(frozen=True, eq=False)
class SpatialGraph:
    """An undirected waypoint graph with geometric neighbour slots.

    Attributes:
        positions: Waypoint positions in metres, ``(num_nodes, 2)`` float64, +x east, +y north.
        neighbors: Neighbour of each waypoint in each slot (east, north, west, south),
            ``(num_nodes, 4)`` int64, ``-1`` where absent. Symmetric: if ``v`` is the east
            neighbour of ``u`` then ``u`` is the west neighbour of ``v``.
        cell_size: Lattice spacing in metres; edge features are distances divided by it.
        cells: ``(row, col)`` grid cell of each waypoint, ``(num_nodes, 2)`` int64, or ``None``
            for graphs not built from a grid.

    Raises:
        ValueError: on construction, naming the argument: positions not ``(num_nodes, 2)`` or
            not finite (the first bad waypoint), indices that are not integers (the first bad
            entry) or outside ``[-1, num_nodes)``, or a non-positive or non-finite cell size.
    """

    positions: np.ndarray  # (num_nodes, 2) float64
    neighbors: np.ndarray  # (num_nodes, 4) int64
    cell_size: float = 1.0
    cells: np.ndarray | None = None  # (num_nodes, 2) int64

    def __post_init__(self) -> None:
        positions = np.asarray(self.positions, dtype=np.float64)
        given = np.asarray(self.neighbors)
        neighbors = as_node_indices(given, "neighbors").reshape(given.shape)
        if positions.ndim != 2 or positions.shape[1] != 2:
            raise ValueError(f"positions must have shape (num_nodes, 2), got {positions.shape}")
        check_finite(positions, "positions")
        if neighbors.shape != (positions.shape[0], NUM_SLOTS):
            raise ValueError(
                f"neighbors must have shape ({positions.shape[0]}, {NUM_SLOTS}), "
                f"got {neighbors.shape}"
            )
        if positions.shape[0] == 0:
            raise ValueError("a SpatialGraph needs at least one waypoint")
        if neighbors.min() < -1 or neighbors.max() >= positions.shape[0]:
            raise ValueError("neighbors holds an index outside [-1, num_nodes)")
        if not (np.isfinite(self.cell_size) and self.cell_size > 0):
            raise ValueError(f"cell_size must be positive and finite, got {self.cell_size}")
        object.__setattr__(self, "positions", positions)
        object.__setattr__(self, "neighbors", neighbors)
        if self.cells is not None:
            cells = np.asarray(self.cells)
            cells = as_node_indices(cells, "cells").reshape(cells.shape)
            object.__setattr__(self, "cells", cells)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_edges(
        cls,
        positions: np.ndarray,
        edges: np.ndarray | list[tuple[int, int]],
        cell_size: float = 1.0,
    ) -> SpatialGraph:
        """Builds a graph from positions and undirected edges, assigning slots by direction.

        Each edge goes into the slot (east, north, west, south) nearest to its direction.

        Args:
            positions: ``(num_nodes, 2)`` positions in metres.
            edges: ``(num_edges, 2)`` undirected node pairs, each listed once.
            cell_size: Lattice spacing in metres.

        Raises:
            ValueError: ``positions`` is not ``(num_nodes, 2)`` or not finite, ``edges`` holds
                a non-integer, an edge names a node outside ``[0, num_nodes)``, is a self-loop
                or is listed twice, or two neighbours of one node fall into the same direction
                slot.
        """
        positions = np.asarray(positions, dtype=np.float64)
        edges = as_node_indices(edges, "edges").reshape(-1, 2)
        if positions.ndim != 2 or positions.shape[1] != 2:
            raise ValueError(f"positions must have shape (num_nodes, 2), got {positions.shape}")
        check_finite(positions, "positions")
        num_nodes = positions.shape[0]
        outside = (edges < 0) | (edges >= num_nodes)
        if outside.any():
            u, v = edges[np.flatnonzero(outside.any(axis=1))[0]]
            raise ValueError(f"edge ({u}, {v}) names a node outside [0, {num_nodes})")
        # each edge in both directions, in edge order: (u0, v0), (v0, u0), (u1, v1), ...
        src, dst = edges.reshape(-1), edges[:, ::-1].reshape(-1)  # (2 E,)
        slot = np.argmax((positions[dst] - positions[src]) @ SLOT_DIRECTIONS.T, axis=1)
        key = src * NUM_SLOTS + slot
        order = np.argsort(key, kind="stable")
        repeat = np.flatnonzero(key[order][1:] == key[order][:-1]) + 1
        # errors as an edge-by-edge construction meets them: the first in edge order
        clash = int(order[repeat].min()) if len(repeat) else len(src)
        loops = np.flatnonzero(edges[:, 0] == edges[:, 1])
        if len(loops) and 2 * loops[0] <= clash:
            u = int(edges[loops[0], 0])
            raise ValueError(f"edge ({u}, {u}) is a self-loop")
        if clash < len(src):
            first = int(order[np.flatnonzero(key[order] == key[clash])[0]])
            raise ValueError(
                f"node {src[clash]} has two neighbours in slot '{SLOT_NAMES[slot[clash]]}': "
                f"{dst[first]} and {dst[clash]}"
            )
        neighbors = np.full((num_nodes, NUM_SLOTS), -1, dtype=np.int64)
        neighbors[src, slot] = dst
        return cls(positions, neighbors, cell_size)

    @classmethod
    def from_cells(
        cls,
        cells: np.ndarray,
        cell_size: float,
        num_rows: int,
        origin: tuple[float, float] = (0.0, 0.0),
    ) -> SpatialGraph:
        """Builds the 4-connected lattice over grid cells.

        Args:
            cells: ``(num_nodes, 2)`` distinct ``(row, col)`` cells, any order; nodes keep it.
            cell_size: Cell size in metres.
            num_rows: Rows of the grid; row 0 is the northern edge.
            origin: Position in metres of the grid's south-west corner.
        """
        cells = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
        rows, cols = cells[:, 0], cells[:, 1]
        width = int(cols.max()) + 3 if len(cols) else 1
        keys = (rows + 1) * width + (cols + 1)
        order = np.argsort(keys)
        sorted_keys = keys[order]
        # east, north, west, south neighbours of a cell: (0, +1), (-1, 0), (0, -1), (+1, 0)
        offsets = np.array([1, -width, -1, width], dtype=np.int64)
        query = keys[:, None] + offsets[None, :]  # (num_nodes, 4)
        pos = np.searchsorted(sorted_keys, query).clip(max=len(keys) - 1)
        found = sorted_keys[pos] == query
        neighbors = np.where(found, order[pos], -1)
        x = origin[0] + (cols + 0.5) * cell_size
        y = origin[1] + (num_rows - rows - 0.5) * cell_size
        return cls(np.stack([x, y], axis=1), neighbors, float(cell_size), cells)

    # ------------------------------------------------------------------ structure
    @property
    def num_nodes(self) -> int:
        """Number of waypoints."""
        return int(self.positions.shape[0])

    @cached_property
    def degree(self) -> np.ndarray:
        """Number of neighbours of each waypoint, ``(num_nodes,)`` int64."""
        return (self.neighbors >= 0).sum(axis=1)

    @property
    def num_edges(self) -> int:
        """Number of directed edges (each undirected edge counts twice)."""
        return int(self.degree.sum())

    @cached_property
    def edge_index(self) -> np.ndarray:
        """Directed edges ``(2, num_edges)`` as ``[sender; receiver]``, by sender then slot."""
        senders = np.repeat(np.arange(self.num_nodes), NUM_SLOTS).reshape(-1, NUM_SLOTS)
        valid = self.neighbors >= 0
        return np.stack([senders[valid], self.neighbors[valid]])

    @cached_property
    def neighbor_distances(self) -> np.ndarray:
        """Distance in cells to each slot's neighbour, ``(num_nodes, 4)`` float32 (0 if absent)."""
        safe = np.where(self.neighbors >= 0, self.neighbors, np.arange(self.num_nodes)[:, None])
        delta = self.positions[safe] - self.positions[:, None, :]
        return (np.linalg.norm(delta, axis=-1) / self.cell_size).astype(np.float32)

    @cached_property
    def float_cells(self) -> np.ndarray:
        """Positions in cells, ``(num_nodes, 2)`` float32, C-contiguous."""
        return np.ascontiguousarray((self.positions / self.cell_size).astype(np.float32))

    @cached_property
    def complex_cells(self) -> np.ndarray:
        """Positions in cells as ``x + iy``, ``(num_nodes,)`` complex64 (one item per node)."""
        return self.float_cells.view(np.complex64).reshape(-1)

    @cached_property
    def adjacency(self) -> csr_matrix:
        """Unweighted symmetric adjacency in CSR form, ``(num_nodes, num_nodes)``."""
        valid = self.neighbors >= 0
        indptr = np.concatenate([[0], np.cumsum(valid.sum(axis=1))])
        indices = self.neighbors[valid]
        data = np.ones(len(indices), dtype=np.float64)
        return csr_matrix((data, indices, indptr), shape=(self.num_nodes, self.num_nodes))

    def validate(self) -> None:
        """Checks that the neighbour table is symmetric and slot-consistent.

        Raises:
            ValueError: naming the first node whose neighbour does not point back.
        """
        opposite = np.array([2, 3, 0, 1])
        u, slot = np.nonzero(self.neighbors >= 0)
        v = self.neighbors[u, slot]
        back = self.neighbors[v, opposite[slot]]
        bad = np.flatnonzero(back != u)
        if len(bad):
            i = bad[0]
            raise ValueError(
                f"neighbour table is not symmetric: node {u[i]} has {v[i]} in slot "
                f"'{SLOT_NAMES[slot[i]]}' but {v[i]} has {back[i]} in the opposite slot"
            )

    # ------------------------------------------------------------------ derived graphs
    def subgraph(self, nodes: np.ndarray) -> SpatialGraph:
        """The graph induced by ``nodes`` (kept in the given order, relabelled ``0..n-1``)."""
        nodes = np.asarray(nodes, dtype=np.int64)
        relabel = np.full(self.num_nodes + 1, -1, dtype=np.int64)  # index -1 maps to -1
        relabel[nodes] = np.arange(len(nodes))
        neighbors = relabel[self.neighbors[nodes]]
        cells = None if self.cells is None else self.cells[nodes]
        return SpatialGraph(self.positions[nodes], neighbors, self.cell_size, cells)

    def component_labels(self) -> np.ndarray:
        """Connected-component label of each waypoint, ``(num_nodes,)``."""
        _, labels = connected_components(self.adjacency, directed=False)
        return labels

    def largest_component(self) -> SpatialGraph:
        """The subgraph of the largest connected component (ties: the lowest label)."""
        labels = self.component_labels()
        counts = np.bincount(labels)
        if len(counts) == 1:
            return self
        return self.subgraph(np.flatnonzero(labels == np.argmax(counts)))

    # ------------------------------------------------------------------ distances
    def hop_distances(self, sources: np.ndarray, limit: float = np.inf) -> np.ndarray:
        """Hop distances from each source, ``(len(sources), num_nodes)``, ``inf`` past ``limit``.

        Cost is proportional to the nodes within ``limit`` hops of the sources, plus the size of
        the output.
        """
        sources = np.asarray(sources, dtype=np.int64)
        return dijkstra(self.adjacency, indices=sources, unweighted=True, limit=limit)

    def nearest_distance(self, sources: np.ndarray, limit: float = np.inf) -> np.ndarray:
        """Hop distance from every node to the nearest of ``sources``, ``(num_nodes,)``.

        ``inf`` where no source lies within ``limit`` hops (or there is no source).
        """
        sources = np.asarray(sources, dtype=np.int64)
        if len(sources) == 0:
            return np.full(self.num_nodes, np.inf)
        return dijkstra(
            self.adjacency, indices=sources, unweighted=True, limit=limit, min_only=True
        )

    def bfs_ball(self, center: int, min_size: int) -> np.ndarray:
        """Nodes of the smallest complete breadth-first layer ball around ``center`` that holds
        at least ``min_size`` nodes (or the whole component), sorted by index."""
        dist = self.hop_distances(np.array([center]))[0]
        finite = np.sort(dist[np.isfinite(dist)])
        radius = finite[min(min_size, len(finite)) - 1]
        return np.flatnonzero(dist <= radius)
