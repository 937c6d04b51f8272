"""The nearest waypoint of points in the plane, for robots that fly between waypoints."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from marl_cover.dynamics import compiled_kernels


class WaypointLocator:
    """Nearest waypoint of points in the plane.

    On a lattice map (every waypoint on a square grid of ``cell_size``) the nearest waypoint of
    a point is the grid point it rounds to, when that grid point is a waypoint: a table lookup.
    Points that round to an empty grid point, and maps off the lattice, use a k-d tree.

    Args:
        graph: The map.
        backend: The table lookup in numpy or by a compiled kernel (``DynamicsConfig.backend``;
            the same numbers).
    """

    def __init__(self, graph: Any, backend: str = "auto") -> None:
        self.graph = graph
        self._kernels = compiled_kernels(backend)
        self._tree = cKDTree(graph.positions)
        self._origin = graph.positions.min(axis=0)
        index = np.rint((graph.positions - self._origin) / graph.cell_size).astype(np.int64)
        on_lattice = np.allclose(
            index * graph.cell_size + self._origin, graph.positions, rtol=0, atol=1e-6
        )
        self._table: np.ndarray | None = None
        if on_lattice and len(np.unique(index, axis=0)) == graph.num_nodes:
            self._table = np.full(index.max(axis=0) + 1, -1, dtype=np.int64)
            self._table[index[:, 0], index[:, 1]] = np.arange(graph.num_nodes)

    def nearest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest waypoint ``(P,)`` of each point ``(P, >=2)`` (its first two coordinates) and
        the distance to it ``(P,)``."""
        xy = points[:, :2]
        if self._table is None:
            dist, node = self._tree.query(xy)
            return node.astype(np.int64), dist
        if self._kernels is not None:
            return self._nearest_compiled(xy)
        index = np.rint((xy - self._origin) / self.graph.cell_size).astype(np.int64)
        inside = ((index >= 0) & (index < self._table.shape)).all(axis=1)
        node = np.full(len(xy), -1, dtype=np.int64)
        node[inside] = self._table[index[inside, 0], index[inside, 1]]
        missing = np.flatnonzero(node < 0)
        if len(missing):
            node[missing] = self._tree.query(xy[missing])[1]
        offset = xy - self.graph.positions[node]
        return node, np.sqrt(np.einsum("ij,ij->i", offset, offset))

    def _nearest_compiled(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`nearest` on the lattice by the compiled kernel (the k-d tree for the rest)."""
        node = np.empty(len(xy), dtype=np.int64)
        dist = np.empty(len(xy))
        positions = self.graph.positions
        args = (self._origin, float(self.graph.cell_size), self._table, positions, node, dist)
        if self._kernels.lattice_nearest(xy, *args):
            missing = np.flatnonzero(node < 0)
            node[missing] = self._tree.query(xy[missing])[1]
            offset = xy[missing] - positions[node[missing]]
            dist[missing] = np.sqrt(np.einsum("ij,ij->i", offset, offset))
        return node, dist
