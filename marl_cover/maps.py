"""Occupancy grids to waypoint graphs, random windows, and the paper's urban map.

The paper (Tolstaya et al.) turns a boolean occupancy grid (``True`` = building) with 5 m cells
into a lattice of waypoints: the free cells within ``perimeter`` cells (Euclidean, in cell
units) of an obstacle, 4-connected, largest connected component kept. On the paper's map
``grid_slice10.npy`` this gives 1266 waypoints for ``perimeter=2`` and 5659 for ``perimeter=12``.
Training graphs are random windows of one third of that graph's bounding box per axis.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from scipy.ndimage import distance_transform_edt

from marl_cover.errors import BadFileError, MissingFileError
from marl_cover.graph import SpatialGraph
from marl_cover.paper_map import paper_map_path

PAPER_CELL_SIZE = 5.0
#: Perimeter of the paper's training graph (1266 waypoints) and generalization graph (5659).
PAPER_PERIMETER = 2.0
PAPER_LARGE_PERIMETER = 12.0
#: Side of the paper's training windows, as a fraction of its graph's bounding box per axis.
PAPER_WINDOW_FRACTION = 1.0 / 3.0


def load_occupancy(path: str | os.PathLike[str]) -> np.ndarray:
    """Reads an occupancy grid: ``True`` where a cell is occupied.

    ``.npy`` files hold a 2-D boolean (or 0/1 integer) array. Images (``.png`` and anything
    Pillow reads) are converted to grey levels; dark pixels (< 128) are occupied.

    Raises:
        MissingFileError: the file does not exist.
        BadFileError: the file is not a readable 2-D grid, naming the file and the problem.
    """
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(path, "occupancy grid not found")
    try:
        if path.suffix.lower() == ".npy":
            with open(path, "rb") as handle:
                grid = np.load(handle, allow_pickle=False)
        else:
            from PIL import Image

            with Image.open(path) as image:
                grid = np.asarray(image.convert("L")) < 128
        return as_occupancy(grid, "grid")
    except ImportError:
        raise
    except Exception as error:  # noqa: BLE001 (numpy, zip and image errors alike)
        kind = ".npy" if path.suffix.lower() == ".npy" else "image"
        problem = " ".join(str(error).split())
        raise BadFileError(path, f"not a readable {kind} occupancy grid ({problem})") from None


def as_occupancy(grid: np.ndarray, name: str = "occupied") -> np.ndarray:
    """``grid`` as a boolean occupancy grid ``(rows, cols)``.

    Raises:
        ValueError: it is not a non-empty 2-D array of booleans or of 0/1 numbers, naming it.
    """
    grid = np.asarray(grid)
    if grid.dtype != np.bool_:
        if not np.issubdtype(grid.dtype, np.number) or not np.isin(grid, (0, 1)).all():
            raise ValueError(f"{name}: expected a boolean or 0/1 grid, got dtype {grid.dtype}")
        grid = grid.astype(bool)
    if grid.ndim != 2 or min(grid.shape) == 0:
        raise ValueError(f"{name}: expected a non-empty 2-D grid, got shape {grid.shape}")
    return grid


def candidate_cells(occupied: np.ndarray, perimeter: float | None) -> np.ndarray:
    """Free cells that may hold a waypoint, ``(num_cells, 2)`` ``(row, col)`` in row-major order.

    Args:
        occupied: ``(rows, cols)`` bool, ``True`` = obstacle.
        perimeter: Keep only free cells whose Euclidean distance (in cells) to the nearest
            obstacle is at most this; ``None`` keeps every free cell.
    """
    free = ~np.asarray(occupied, dtype=bool)
    if perimeter is not None:
        if not (~free).any():
            raise ValueError("perimeter is set but the grid has no obstacle")
        free &= distance_transform_edt(free) <= perimeter
    return np.argwhere(free)


def graph_from_occupancy(
    occupied: np.ndarray,
    cell_size: float = PAPER_CELL_SIZE,
    perimeter: float | None = None,
    origin: tuple[float, float] = (0.0, 0.0),
    largest_component: bool = True,
) -> SpatialGraph:
    """The 4-connected waypoint lattice over the free cells of an occupancy grid.

    Args:
        occupied: ``(rows, cols)`` bool, ``True`` = obstacle; row 0 is the northern edge.
        cell_size: Cell size in metres (5 m in the paper).
        perimeter: See :func:`candidate_cells`.
        origin: Position in metres of the grid's south-west corner.
        largest_component: Keep only the largest connected component.

    Raises:
        ValueError: ``occupied`` is not a 2-D grid of booleans or 0/1, or no free cell qualifies.
    """
    occupied = as_occupancy(occupied)
    cells = candidate_cells(occupied, perimeter)
    if len(cells) == 0:
        raise ValueError("the occupancy grid has no free cell to place a waypoint on")
    graph = SpatialGraph.from_cells(cells, cell_size, occupied.shape[0], origin)
    return graph.largest_component() if largest_component else graph


def window_size(graph: SpatialGraph, fraction: float) -> np.ndarray:
    """Window extent in metres per axis: ``fraction`` of the bounding box of ``graph``."""
    return (graph.positions.max(axis=0) - graph.positions.min(axis=0)) * fraction


def sample_window(
    graph: SpatialGraph,
    rng: np.random.Generator,
    fraction: float = PAPER_WINDOW_FRACTION,
    min_nodes: int = 200,
    max_tries: int = 10_000,
) -> SpatialGraph:
    """A random window of ``graph``, as the paper draws its training graphs.

    The window covers ``fraction`` of the bounding box per axis, its lower corner uniform in
    ``[min, max - size]``; it keeps the waypoints with ``lo <= p < hi`` and then their largest
    connected component, redrawing until that holds at least ``min_nodes`` waypoints.

    Raises:
        RuntimeError: no window qualified in ``max_tries`` draws.
    """
    lo_all = graph.positions.min(axis=0)
    size = window_size(graph, fraction)
    span = graph.positions.max(axis=0) - size - lo_all
    for _ in range(max_tries):
        lo = lo_all + rng.random(2) * span
        inside = np.all((graph.positions >= lo) & (graph.positions < lo + size), axis=1)
        if inside.sum() < min_nodes:
            continue
        window = graph.subgraph(np.flatnonzero(inside)).largest_component()
        if window.num_nodes >= min_nodes:
            return window
    raise RuntimeError(
        f"no window of fraction {fraction:.3f} with >= {min_nodes} waypoints in {max_tries} draws"
    )


def max_window_nodes(graph: SpatialGraph, fraction: float) -> int:
    """An upper bound on the waypoints any window of :func:`sample_window` can hold.

    Exact for grid graphs (a maximum over every window placement, from a summed-area table of
    the cells); ``num_nodes`` for graphs without cells.
    """
    if graph.cells is None:
        return graph.num_nodes
    size = window_size(graph, fraction) / graph.cell_size
    # A half-open window of extent s covers at most floor(s) + 1 cell centres per axis.
    span = np.floor(size).astype(np.int64) + 1
    cells = graph.cells - graph.cells.min(axis=0)
    rows, cols = cells.max(axis=0) + 1
    counts = np.zeros((rows + 1, cols + 1), dtype=np.int64)
    np.add.at(counts, (cells[:, 0] + 1, cells[:, 1] + 1), 1)
    table = counts.cumsum(axis=0).cumsum(axis=1)
    h, w = min(span[1], rows), min(span[0], cols)  # y extent spans rows, x extent spans columns
    sums = table[h:, w:] - table[:-h, w:] - table[h:, :-w] + table[:-h, :-w]
    return int(sums.max())


def paper_graph(perimeter: float = PAPER_PERIMETER) -> SpatialGraph:
    """The paper's urban waypoint graph (1266 waypoints at perimeter 2, 5659 at perimeter 12)."""
    return graph_from_occupancy(
        load_occupancy(paper_map_path()), PAPER_CELL_SIZE, perimeter=perimeter
    )
