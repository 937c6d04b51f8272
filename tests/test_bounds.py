"""Upper bounds on any policy's reward: exact values on hand-built graphs, never below a played
episode, the route bound never above the reach bound."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_grid_graph

import marl_cover
from marl_cover.agents.baselines.greedy import CentralizedGreedyPolicy
from marl_cover.agents.evaluation.bounds import episode_bound, reach_bound, route_bound
from marl_cover.agents.evaluation.episodes import run_episode
from marl_cover.graph import SpatialGraph


@pytest.fixture
def cross() -> SpatialGraph:
    """A centre (0) and four arms of three waypoints: arm ``a`` holds 1 + 3a, 2 + 3a, 3 + 3a,
    from the centre out (cell size 1)."""
    positions, edges = [(0.0, 0.0)], []
    for arm, (dx, dy) in enumerate(((1, 0), (0, 1), (-1, 0), (0, -1))):
        for k in range(1, 4):
            positions.append((k * dx, k * dy))
            edges.append((0 if k == 1 else 3 * arm + k - 1, 3 * arm + k))
    return SpatialGraph.from_edges(np.array(positions), edges, cell_size=1.0)


def _open(num_nodes: int, nodes: list[int]) -> np.ndarray:
    mask = np.zeros(num_nodes, dtype=bool)
    mask[nodes] = True
    return mask


def test_route_bound_counts_moves(cross) -> None:
    adjacency, arms = cross.adjacency, list(range(1, 13))
    everything = _open(13, arms)
    assert reach_bound(adjacency, np.array([0]), everything, 3) == 12
    assert route_bound(adjacency, np.array([0]), everything, 3) == 3  # one waypoint a move
    assert route_bound(adjacency, np.array([0]), everything, 7) == 7
    assert route_bound(adjacency, np.array([0]), everything, 30) == 12
    tips = _open(13, [3, 6, 9, 12])  # three hops out, each
    assert reach_bound(adjacency, np.array([0]), tips, 3) == 4
    assert route_bound(adjacency, np.array([0]), tips, 3) == 1  # only move 3 reaches a tip
    assert route_bound(adjacency, np.array([0]), tips, 4) == 2  # moves 3 and 4
    # a second robot one hop out on arm 0: its own tip is two hops away, the others four
    assert route_bound(adjacency, np.array([0, 1]), tips, 3) == 2
    assert reach_bound(adjacency, np.array([0, 1]), tips, 3) == 4
    assert route_bound(adjacency, np.array([0]), tips, 0) == 0
    assert route_bound(adjacency, np.array([0]), _open(13, []), 5) == 0


def test_path_graph_bounds_are_exact(path_graph) -> None:
    everything = _open(8, list(range(1, 8)))
    for steps in range(9):
        expected = min(steps, 7)  # walking east visits one new point a move
        assert route_bound(path_graph.adjacency, np.array([0]), everything, steps) == expected
        assert reach_bound(path_graph.adjacency, np.array([0]), everything, steps) == expected


@pytest.mark.parametrize("task", ["coverage", "exploration"])
def test_bounds_hold_over_played_episodes(task: str) -> None:
    rng = np.random.default_rng(3)
    graph = random_grid_graph(rng, 14, 14, 0.8)
    env = marl_cover.parallel_env(graph=graph, num_robots=5, hops=4, max_steps=12, task=task)
    policy = CentralizedGreedyPolicy(4, fallback="random", seed=0)
    for seed in range(6):
        route, reach = episode_bound(env, seed, "route"), episode_bound(env, seed, "reach")
        reward = run_episode(env, policy, seed).reward
        assert reward <= route < reach  # 5 robots x 12 moves: fewer than the reachable points
    with pytest.raises(ValueError, match="kind must be one of"):
        episode_bound(env, 0, "tight")


def test_route_bound_golden_on_a_city() -> None:
    env = marl_cover.parallel_env(num_robots=100, map="city", city_size=5659, max_steps=50)
    assert [episode_bound(env, seed, "route") for seed in range(2)] == [1087, 1144]
    assert [episode_bound(env, seed, "reach") for seed in range(2)] == [1136, 1203]
