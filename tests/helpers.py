"""Helpers shared by the tests."""

from __future__ import annotations

import numpy as np

from marl_cover.graph import SpatialGraph


def random_grid_graph(
    rng: np.random.Generator, rows: int, cols: int, density: float
) -> SpatialGraph:
    """The largest component of a random set of grid cells."""
    from marl_cover.maps import graph_from_occupancy

    occupied = rng.random((rows, cols)) > density
    occupied[rng.integers(rows), rng.integers(cols)] = False
    return graph_from_occupancy(occupied, cell_size=5.0)
