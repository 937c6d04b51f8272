"""Graphs and maps: slots, lattices, the paper's map counts, windows, cities, file loading."""

from __future__ import annotations

import numpy as np
import pytest

import marl_cover
from marl_cover.city import CityConfig, generate_city
from marl_cover.errors import BadFileError
from marl_cover.graph import SpatialGraph
from marl_cover.maps import (
    candidate_cells,
    graph_from_occupancy,
    load_occupancy,
    max_window_nodes,
    paper_graph,
    paper_map_path,
    sample_window,
)


def test_slots_follow_geometry(tee_graph: SpatialGraph) -> None:
    # east, north, west, south
    assert tee_graph.neighbors.tolist() == [
        [1, -1, -1, -1],
        [2, 4, 0, -1],
        [3, -1, 1, -1],
        [-1, -1, 2, -1],
        [-1, 5, -1, 1],
        [-1, -1, -1, 4],
    ]
    tee_graph.validate()
    assert tee_graph.num_edges == 10
    assert tee_graph.degree.tolist() == [1, 3, 2, 1, 2, 1]


def test_from_edges_rejects_two_neighbours_in_one_slot() -> None:
    positions = np.array([(0, 0), (1, 0.1), (1, -0.1)], float)
    with pytest.raises(ValueError, match="two neighbours in slot 'east'"):
        SpatialGraph.from_edges(positions, [(0, 1), (0, 2)])
    with pytest.raises(ValueError, match=r"edge \(1, 5\) names a node outside \[0, 3\)"):
        SpatialGraph.from_edges(positions, [(0, 1), (1, 5)])
    with pytest.raises(ValueError, match=r"edge \(0, -1\) names a node outside"):
        SpatialGraph.from_edges(positions, [(0, -1)])
    with pytest.raises(
        ValueError, match=r"positions must have shape \(num_nodes, 2\), got \(3, 3\)"
    ):
        SpatialGraph.from_edges(np.zeros((3, 3)), [(0, 1)])
    with pytest.raises(ValueError, match=r"edge \(0, 0\) is a self-loop"):
        SpatialGraph.from_edges(positions, [(0, 0)])


def test_lattice_from_grid_drops_diagonals_and_small_components() -> None:
    occupied = np.array(
        [
            [0, 0, 1, 0],
            [1, 0, 1, 1],
            [0, 1, 1, 0],
        ],
        dtype=bool,
    )
    graph = graph_from_occupancy(occupied, cell_size=2.0)
    # free cells: (0,0) (0,1) (1,1) connected; (0,3), (2,0), (2,3) isolated
    assert graph.cells.tolist() == [[0, 0], [0, 1], [1, 1]]
    assert graph.positions.tolist() == [[1.0, 5.0], [3.0, 5.0], [3.0, 3.0]]
    assert graph.neighbors.tolist() == [[1, -1, -1, -1], [-1, -1, 0, 2], [-1, 1, -1, -1]]
    whole = graph_from_occupancy(occupied, cell_size=2.0, largest_component=False)
    assert whole.num_nodes == 6 and whole.num_edges == 4


def test_hop_distances_and_bfs_ball(tee_graph: SpatialGraph) -> None:
    dist = tee_graph.hop_distances(np.array([0, 5]), limit=2)
    assert dist[0].tolist() == [0, 1, 2, np.inf, 2, np.inf]
    assert dist[1].tolist() == [np.inf, 2, np.inf, np.inf, 1, 0]
    assert tee_graph.nearest_distance(np.array([3, 5])).tolist() == [3, 2, 1, 0, 1, 0]
    # smallest full-layer ball with >= 3 nodes around 0: layers {0}, {1}, {2, 4}
    assert tee_graph.bfs_ball(0, 3).tolist() == [0, 1, 2, 4]
    assert tee_graph.bfs_ball(0, 100).tolist() == [0, 1, 2, 3, 4, 5]


def test_subgraph_relabels(tee_graph: SpatialGraph) -> None:
    sub = tee_graph.subgraph(np.array([1, 4, 5]))
    assert sub.neighbors.tolist() == [[-1, 1, -1, -1], [-1, 2, -1, 0], [-1, -1, -1, 1]]
    sub.validate()


def test_paper_map_counts(paper_map_available: None) -> None:
    occupied = load_occupancy(paper_map_path())
    assert occupied.shape == (128, 110)
    assert len(candidate_cells(occupied, 2.0)) == 1714
    assert len(candidate_cells(occupied, 12.0)) == 5855
    small, large = paper_graph(2.0), paper_graph(12.0)
    assert small.num_nodes == 1266 and small.num_edges == 3552
    assert np.bincount(small.degree).tolist() == [0, 33, 375, 663, 195]
    assert large.num_nodes == 5659 and large.num_edges == 20910
    assert np.bincount(large.degree).tolist() == [0, 30, 421, 794, 4414]
    small.validate()
    large.validate()


def test_paper_windows(paper_map_available: None) -> None:
    graph = paper_graph(2.0)
    rng = np.random.default_rng(0)
    sizes = np.array([sample_window(graph, rng).num_nodes for _ in range(2000)])
    assert abs(sizes.mean() - 228) <= 2
    assert sizes.min() >= 200
    assert sizes.max() <= max_window_nodes(graph, 1 / 3)
    again = [sample_window(graph, np.random.default_rng(0)).num_nodes for _ in range(1)]
    assert again[0] == sizes[0]


def test_paper_preset_window_fraction(paper_map_available: None) -> None:
    from marl_cover.config import CoverageConfig
    from marl_cover.sources import WindowMap, make_map_source

    graph = paper_graph(2.0)
    default = make_map_source(CoverageConfig(map="paper"))
    wider = make_map_source(CoverageConfig(map="paper", window_fraction=0.5))
    assert isinstance(default, WindowMap) and isinstance(wider, WindowMap)
    assert default.fraction == 1 / 3
    assert wider.max_waypoints == max_window_nodes(graph, 0.5) > default.max_waypoints
    # The same generator draws the same window a sampler of that fraction draws.
    drawn = wider.sample(np.random.default_rng(3))
    assert drawn.num_nodes == sample_window(graph, np.random.default_rng(3), 0.5).num_nodes
    assert drawn.num_nodes <= wider.max_waypoints


def test_paper_map_variable_naming_no_file_is_an_error(tmp_path, monkeypatch) -> None:
    missing = tmp_path / "nowhere.npy"
    monkeypatch.setenv("MARL_COVER_PAPER_MAP", str(missing))
    with pytest.raises(
        FileNotFoundError, match=f"{missing}: \\$MARL_COVER_PAPER_MAP names no file"
    ):
        paper_map_path()  # not another copy found elsewhere


def test_large_maps_load_fast() -> None:
    import time

    rng = np.random.default_rng(0)
    occupied = rng.random((400, 400)) < 0.15  # 160,000 cells, about 136,000 free
    start = time.perf_counter()
    graph = graph_from_occupancy(occupied)
    elapsed = time.perf_counter() - start
    assert graph.num_nodes > 50_000
    assert elapsed < 1.0, f"a {graph.num_nodes}-waypoint map took {elapsed:.2f} s"


def test_load_occupancy_formats_and_errors(tmp_path) -> None:
    from PIL import Image

    grid = np.array([[0, 1], [1, 0]], dtype=bool)
    np.save(tmp_path / "grid.npy", grid)
    assert (load_occupancy(tmp_path / "grid.npy") == grid).all()
    Image.fromarray(np.where(grid, 0, 255).astype(np.uint8)).save(tmp_path / "grid.png")
    assert (load_occupancy(tmp_path / "grid.png") == grid).all()
    np.save(tmp_path / "bad.npy", np.array([[0.5, 1.0]]))
    with pytest.raises(BadFileError, match=r"bad.npy: .*expected a boolean or 0/1 grid"):
        load_occupancy(tmp_path / "bad.npy")
    with pytest.raises(FileNotFoundError, match="missing.npy"):
        load_occupancy(tmp_path / "missing.npy")
    (tmp_path / "garbage.npy").write_bytes(b"not an array")
    with pytest.raises(ValueError, match=r"garbage\.npy: not a readable \.npy occupancy grid"):
        load_occupancy(tmp_path / "garbage.npy")


@pytest.mark.parametrize(
    ("grid", "message"),
    [
        (
            np.zeros((3, 3, 3), dtype=bool),
            r"occupied: expected a non-empty 2-D grid, got shape \(3, 3, 3\)",
        ),
        (
            np.zeros((0, 4), dtype=bool),
            r"occupied: expected a non-empty 2-D grid, got shape \(0, 4\)",
        ),
        (
            np.array([[0.5, 2.0], [3.0, -1.0]]),
            "occupied: expected a boolean or 0/1 grid, got dtype float64",
        ),
    ],
)
def test_grids_in_memory_are_checked_like_files(grid: np.ndarray, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        graph_from_occupancy(grid, cell_size=5.0)


def test_a_grid_file_without_free_cells_is_named(tmp_path) -> None:
    import marl_cover

    np.save(tmp_path / "walls.npy", np.ones((6, 6), dtype=bool))
    with pytest.raises(ValueError, match=r"walls\.npy: the occupancy grid has no free cell"):
        marl_cover.parallel_env(map=str(tmp_path / "walls.npy"))


@pytest.mark.parametrize("size", [100, 228, 5000, 100_000])
def test_city_has_exact_size_and_is_connected(size: int) -> None:
    graph = generate_city(np.random.default_rng(size), CityConfig(num_waypoints=size))
    assert graph.num_nodes == size
    assert len(np.unique(graph.component_labels())) == 1
    graph.validate()


def test_city_is_seeded() -> None:
    a = generate_city(np.random.default_rng(3))
    b = generate_city(np.random.default_rng(3))
    c = generate_city(np.random.default_rng(4))
    assert np.array_equal(a.positions, b.positions)
    assert not np.array_equal(a.positions, c.positions)


def test_env_refuses_a_one_way_neighbour_table() -> None:
    positions = np.array([(0, 0), (5, 0)], float)
    one_way = SpatialGraph(positions, np.array([[1, -1, -1, -1], [-1, -1, -1, -1]]), cell_size=5.0)
    with pytest.raises(ValueError, match="not symmetric: node 0 has 1 in slot 'east'"):
        marl_cover.parallel_env(graph=one_way, num_robots=1)
