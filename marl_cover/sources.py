"""Where an environment's maps come from: one fixed graph, random windows, or new cities.

A map source draws the graph of each episode from the environment's generator and states
bounds on every graph it can draw, which fix the padded observation shapes.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from marl_cover.city import CityConfig, generate_city
from marl_cover.config import MAP_PRESETS, CoverageConfig
from marl_cover.errors import BadFileError
from marl_cover.graph import SpatialGraph
from marl_cover.maps import (
    PAPER_LARGE_PERIMETER,
    PAPER_PERIMETER,
    PAPER_WINDOW_FRACTION,
    graph_from_occupancy,
    load_occupancy,
    max_window_nodes,
    paper_graph,
    sample_window,
)


class MapSource:
    """Base class of map sources.

    Attributes:
        max_waypoints: Most waypoints of any graph the source draws.
        max_waypoint_edges: Most directed waypoint-waypoint edges of any graph it draws.
        lattice: Whether every graph is a 4-connected square lattice.
        fixed: Whether every draw returns the same graph.
    """

    max_waypoints: int
    max_waypoint_edges: int
    lattice: bool
    fixed: bool

    def sample(self, rng: np.random.Generator) -> SpatialGraph:
        """The graph of the next episode."""
        raise NotImplementedError


@dataclass
class FixedMap(MapSource):
    """The same graph every episode."""

    graph: SpatialGraph

    def __post_init__(self) -> None:
        self.max_waypoints = self.graph.num_nodes
        self.max_waypoint_edges = self.graph.num_edges
        self.lattice = self.graph.cells is not None
        self.fixed = True

    def sample(self, rng: np.random.Generator) -> SpatialGraph:
        """The same graph every episode."""
        return self.graph


@dataclass
class WindowMap(MapSource):
    """A random window of a larger graph every episode (the paper's training graphs)."""

    graph: SpatialGraph
    fraction: float
    min_nodes: int

    def __post_init__(self) -> None:
        self.max_waypoints = max_window_nodes(self.graph, self.fraction)
        if self.max_waypoints < self.min_nodes:
            raise ValueError(
                f"no window of fraction {self.fraction} can hold {self.min_nodes} waypoints "
                f"(at most {self.max_waypoints})"
            )
        self.max_waypoint_edges = 4 * self.max_waypoints
        self.lattice = self.graph.cells is not None
        self.fixed = False

    def sample(self, rng: np.random.Generator) -> SpatialGraph:
        """A random window of the graph, drawn with ``rng``."""
        return sample_window(self.graph, rng, self.fraction, self.min_nodes)


@dataclass
class CityMap(MapSource):
    """A new procedural city every episode."""

    config: CityConfig

    def __post_init__(self) -> None:
        self.max_waypoints = self.config.num_waypoints
        self.max_waypoint_edges = 4 * self.config.num_waypoints
        self.lattice = True
        self.fixed = False

    def sample(self, rng: np.random.Generator) -> SpatialGraph:
        """A new city drawn with ``rng``."""
        return generate_city(rng, self.config)


@lru_cache(maxsize=8)
def _cached_paper_graph(perimeter: float) -> SpatialGraph:
    return paper_graph(perimeter)


@lru_cache(maxsize=8)
def _cached_grid_graph(path: str, cell_size: float, perimeter: float | None) -> SpatialGraph:
    occupied = load_occupancy(path)  # names the file itself when it cannot be read
    try:
        return graph_from_occupancy(occupied, cell_size, perimeter=perimeter)
    except ValueError as error:  # no usable free cell: say which file
        raise BadFileError(path, str(error)) from error


def make_map_source(config: CoverageConfig) -> MapSource:
    """The map source a configuration asks for.

    Raises:
        FileNotFoundError: the map file (or the paper's map) is missing, naming the path.
        ValueError: the maps are too small for the team, ``map`` is not understood, or a given
            ``graph``'s neighbour table is not symmetric or it has a component smaller than
            the team.
    """
    source: MapSource
    if config.graph is not None:
        config.graph.validate()  # a hand-made table: moves and ego-graphs assume symmetry
        source = FixedMap(config.graph)
    elif config.map == "city":
        source = CityMap(CityConfig(num_waypoints=config.city_size))
    elif config.map == "paper":
        fraction = (
            PAPER_WINDOW_FRACTION if config.window_fraction is None else config.window_fraction
        )
        source = WindowMap(_cached_paper_graph(PAPER_PERIMETER), fraction, config.min_window_nodes)
    elif config.map == "paper_full":
        source = FixedMap(_cached_paper_graph(PAPER_PERIMETER))
    elif config.map == "paper_large":
        source = FixedMap(_cached_paper_graph(PAPER_LARGE_PERIMETER))
    else:
        path = Path(config.map)
        if path.suffix == "" and not path.exists():
            raise ValueError(
                f"map {config.map!r} is neither a preset {MAP_PRESETS} nor a grid file"
            )
        graph = _cached_grid_graph(str(path), config.map_cell_size, config.map_perimeter)
        if config.window_fraction is None:
            source = FixedMap(graph)
        else:
            source = WindowMap(graph, config.window_fraction, config.min_window_nodes)
    smallest = config.min_window_nodes if isinstance(source, WindowMap) else source.max_waypoints
    if smallest < config.num_robots:
        raise ValueError(f"{config.num_robots} robots do not fit on maps of {smallest} waypoints")
    if isinstance(source, FixedMap):
        check_components(source.graph, config.num_robots)
    return source


def check_components(graph: SpatialGraph, num_robots: int) -> None:
    """Checks that every connected component of ``graph`` can hold the team: a reset starts
    the team around a random waypoint, within its component.

    Raises:
        ValueError: naming the smallest component's size, a waypoint in it, and the team's.
    """
    labels = graph.component_labels()
    sizes = np.bincount(labels)  # (num_components,)
    smallest = int(np.argmin(sizes))
    if sizes[smallest] < num_robots:
        waypoint = int(np.flatnonzero(labels == smallest)[0])
        raise ValueError(
            f"the graph has a connected component of {sizes[smallest]} waypoints (waypoint "
            f"{waypoint} is in it), smaller than the team of {num_robots} robots: a reset "
            "that starts the team there would fail; keep graph.largest_component() or "
            "use fewer robots"
        )
