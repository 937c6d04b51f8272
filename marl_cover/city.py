"""Procedural cities: seeded occupancy grids of building blocks, streets and parks.

The library's default map, so that nothing depends on external data. A city is a grid of 5 m
cells crossed by streets of random width at random spacings; each block between streets is
either a park (open ground with a few trees) or is filled with one to four buildings separated
by alleys. Waypoints are placed as in the paper: free cells within ``perimeter`` cells of an
obstacle, 4-connected, largest component, and the graph is cut to exactly the number of
waypoints asked for by a breadth-first ball around the node nearest the city centre.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from marl_cover.graph import SpatialGraph
from marl_cover.maps import graph_from_occupancy

#: Waypoints per cell of city area, measured on generated cities (used to size the grid).
_WAYPOINT_DENSITY = 0.45


@dataclass(frozen=True)
class CityConfig:
    """Parameters of :func:`generate_city`.

    Attributes:
        num_waypoints: Exact number of waypoints of the returned graph (100 to 100,000 tested).
        cell_size: Cell size in metres.
        perimeter: Waypoints are free cells within this many cells of an obstacle.
        block_min: Smallest block side, in cells.
        block_max: Largest block side, in cells.
        street_widths: Street widths to draw from, in cells.
        park_probability: Chance that a block is a park.
        tree_probability: Chance that a park cell holds a tree (a one-cell obstacle).
    """

    num_waypoints: int = 228
    cell_size: float = 5.0
    perimeter: float = 2.0
    block_min: int = 4
    block_max: int = 12
    street_widths: tuple[int, ...] = (1, 1, 2, 3)
    park_probability: float = 0.12
    tree_probability: float = 0.06

    def __post_init__(self) -> None:
        if self.num_waypoints < 1:
            raise ValueError(f"num_waypoints must be >= 1, got {self.num_waypoints}")
        if not 1 <= self.block_min <= self.block_max:
            raise ValueError(
                f"need 1 <= block_min <= block_max, got {self.block_min}, {self.block_max}"
            )


def city_occupancy(
    shape: tuple[int, int], rng: np.random.Generator, config: CityConfig
) -> np.ndarray:
    """A ``(rows, cols)`` occupancy grid of a city, ``True`` = building or tree."""
    rows, cols = shape
    occupied = np.zeros(shape, dtype=bool)
    row_blocks = _blocks(rows, rng, config)
    col_blocks = _blocks(cols, rng, config)
    for r0, r1 in row_blocks:
        for c0, c1 in col_blocks:
            if rng.random() < config.park_probability:
                occupied[r0:r1, c0:c1] = rng.random((r1 - r0, c1 - c0)) < config.tree_probability
            else:
                _fill_block(occupied, r0, r1, c0, c1, rng)
    return occupied


def _blocks(length: int, rng: np.random.Generator, config: CityConfig) -> list[tuple[int, int]]:
    """Half-open block intervals along one axis, separated by streets."""
    blocks = []
    start = int(rng.choice(config.street_widths))
    while start < length:
        end = min(start + int(rng.integers(config.block_min, config.block_max + 1)), length)
        blocks.append((start, end))
        start = end + int(rng.choice(config.street_widths))
    return blocks


def _fill_block(
    occupied: np.ndarray, r0: int, r1: int, c0: int, c1: int, rng: np.random.Generator
) -> None:
    """Fills a block with buildings, split by one-cell alleys along its longer side."""
    horizontal = (c1 - c0) >= (r1 - r0)
    lo, hi = (c0, c1) if horizontal else (r0, r1)
    max_parts = max(1, min(4, (hi - lo + 1) // 4))
    cuts = (
        np.sort(rng.choice(np.arange(lo + 2, hi - 1), size=max_parts - 1, replace=False))
        if (max_parts > 1 and hi - lo > 4)
        else np.array([], dtype=np.int64)
    )
    edges = [lo, *cuts.tolist(), hi]
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        b_end = b if b == hi else b - 1  # leave a one-cell alley before the next building
        if b_end <= a:
            continue
        if horizontal:
            occupied[r0:r1, a:b_end] = True
        else:
            occupied[a:b_end, c0:c1] = True


def generate_city(rng: np.random.Generator, config: CityConfig | None = None) -> SpatialGraph:
    """A procedural city's waypoint graph with exactly ``config.num_waypoints`` waypoints.

    The grid is sized from the expected waypoint density and grown until its largest component
    is big enough; the graph is then the breadth-first ball of exactly ``num_waypoints`` nodes
    (the last layer cut by node index) around the node nearest the grid centre.
    """
    config = config or CityConfig()
    side = int(np.ceil(np.sqrt(1.3 * config.num_waypoints / _WAYPOINT_DENSITY))) + 4
    while True:
        occupied = city_occupancy((side, side), rng, config)
        if occupied.any():
            graph = graph_from_occupancy(occupied, config.cell_size, perimeter=config.perimeter)
            if graph.num_nodes >= config.num_waypoints:
                break
        side = int(side * 1.25) + 2
    centre = graph.positions.mean(axis=0)
    start = int(np.argmin(np.linalg.norm(graph.positions - centre, axis=1)))
    dist = graph.hop_distances(np.array([start]))[0]
    order = np.lexsort((np.arange(graph.num_nodes), dist))[: config.num_waypoints]
    return graph.subgraph(np.sort(order))
