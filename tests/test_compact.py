"""Compact observations: exact tables on a hand-built graph, lossless against the padded mode on
many maps and teams, the PettingZoo checkers, and sizes that do not grow with the team."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from helpers import random_grid_graph
from pettingzoo.test import parallel_api_test, parallel_seed_test

import marl_cover
from marl_cover.compact import CompactObservations, observation_to_padded, padded_to_compact
from marl_cover.ego import EgoScratch, build_ego_graphs, row_table
from marl_cover.graph import SpatialGraph

TABLES = ("node_offsets", "nodes", "edge_offsets", "edge_links", "edge_attr", "action_mask")


def test_compact_tables_of_a_hand_built_graph(path_graph) -> None:
    """Robots on waypoints 0 and 2 of the path 0 - 1 - ... - 7, hops 2, interest on 1."""
    env = marl_cover.parallel_env(
        graph=path_graph, num_robots=2, hops=2, observation_mode="compact", max_steps=9
    )
    obs, _ = env.reset(seed=0, options={"robot_nodes": [0, 2], "interest_nodes": [1, 5]})
    graph = obs["robot_0"]["graph"]
    np.testing.assert_array_equal(
        graph.nodes,
        [
            [1, 0, 0, 0, 0, 0],  # the ego robot
            [0, 1, 0, 0, 0, 0],  # waypoint 0
            [0, 1, 1, 0, 1, 0],  # waypoint 1: an unvisited point of interest, one cell east
            [0, 1, 0, 0, 2, 0],  # waypoint 2
            [1, 0, 0, 0, 2, 0],  # robot 1, on waypoint 2
        ],
    )
    np.testing.assert_array_equal(
        graph.edge_links,
        [
            [1, 0], [2, 0],  # in-edges of the two available actions: stay, east
            [0, 1], [0, 2],  # their out-edges
            [1, 2], [2, 3], [2, 1], [3, 2],  # waypoint edges, by waypoint then slot
            [3, 4], [4, 3], [2, 4], [4, 2],  # robot 1's stay and west edges, both ways
        ],
    )  # fmt: skip
    np.testing.assert_array_equal(graph.edges[:, 0], [0, 1, 0, 1, 1, 1, 1, 1, 0, 0, 1, 1])
    np.testing.assert_array_equal(obs["robot_0"]["action_mask"], [1, 1, 0, 0, 0])
    assert obs["robot_0"]["steps_left"].shape == () and int(obs["robot_0"]["steps_left"]) == 9
    # robot 1 sees waypoints 0..4 and robot 0
    assert obs["robot_1"]["graph"].nodes.shape == (7, 6)
    np.testing.assert_array_equal(obs["robot_1"]["graph"].nodes[-1], [1, 0, 0, 0, -2, 0])
    assert env.observation_space("robot_0").contains(obs["robot_0"])
    padded = observation_to_padded(obs["robot_0"], env.padded_shape)
    reference = env.observe_batch()
    for key, value in padded.items():
        np.testing.assert_array_equal(value, reference[key][0], err_msg=key)


def permuted(graph: SpatialGraph, rng: np.random.Generator) -> SpatialGraph:
    """``graph`` with its waypoints renumbered at random (no longer row by row)."""
    order = rng.permutation(graph.num_nodes)  # new id -> old id
    new_id = np.argsort(order)
    neighbors = graph.neighbors[order]
    neighbors = np.where(neighbors >= 0, new_id[neighbors.clip(min=0)], -1)
    return SpatialGraph(graph.positions[order], neighbors, graph.cell_size)


CASES = [  # (map settings, robots, hops)
    ({"map": "city", "city_size": 228}, 4, 19),
    ({"map": "city", "city_size": 300}, 40, 3),
    ({"map": "city", "city_size": 120, "start_density": 1}, 60, 4),  # a crowd: team > ball
    ({"map": "city", "city_size": 100}, 20, 1),
    ({"map": "city", "city_size": 500, "task": "exploration"}, 30, 19),
    ({"grid": "random"}, 6, 5),
    ({"grid": "permuted"}, 6, 5),  # ids not row by row: the kernels sort each ball
]


@pytest.mark.parametrize("case", range(len(CASES)))
@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_compact_and_padded_agree_key_by_key(case: int, backend: str) -> None:
    if backend == "numba":
        pytest.importorskip("numba")
    settings, num_robots, hops = CASES[case]
    settings = dict(settings)
    rng = np.random.default_rng(case)
    if "grid" in settings:
        graph = random_grid_graph(rng, 14, 16, 0.8)
        settings = {"graph": permuted(graph, rng) if settings["grid"] == "permuted" else graph}
        assert (row_table(settings["graph"]) is None) == (CASES[case][0]["grid"] == "permuted")
    env = marl_cover.parallel_env(
        **settings,
        num_robots=num_robots,
        hops=hops,
        observation_mode="compact",
        ego_backend=backend,
    )
    obs, _ = env.reset(seed=case)
    space = env.observation_space("robot_0")
    for _ in range(5):
        tables, padded = env.observe_compact(), env.observe_batch()
        back = tables.to_padded(env.padded_shape)
        assert back.keys() == padded.keys()
        for key, value in padded.items():
            assert back[key].dtype == value.dtype, key
            np.testing.assert_array_equal(back[key], value, err_msg=key)
        again = padded_to_compact(padded)
        for key in TABLES:
            np.testing.assert_array_equal(getattr(again, key), getattr(tables, key), err_msg=key)
        for i, agent in enumerate(env.possible_agents):
            assert space.contains(obs[agent]), agent
            one = observation_to_padded(obs[agent], env.padded_shape)
            for key, value in one.items():
                np.testing.assert_array_equal(value, padded[key][i], err_msg=f"{agent} {key}")
        obs, *_ = env.step({a: int(rng.integers(5)) for a in env.agents})


def test_compact_env_passes_the_pettingzoo_checkers() -> None:
    config = {"num_robots": 5, "hops": 4, "city_size": 150, "observation_mode": "compact"}
    parallel_api_test(marl_cover.parallel_env(**config), num_cycles=60)
    parallel_seed_test(functools.partial(marl_cover.parallel_env, **config), num_cycles=30)


def test_a_robots_view_ignores_robots_outside_it(path_graph) -> None:
    """A robot's compact observation depends on the robots in its ball only, so adding far
    robots (a larger team) leaves it bit for bit the same."""
    line = SpatialGraph.from_edges(
        np.stack([np.arange(60) * 5.0, np.zeros(60)], axis=1),
        [(i, i + 1) for i in range(59)],
        cell_size=5.0,
    )
    views = []
    for far in (0, 10, 40):
        team = [3, 5] + list(range(20, 20 + far))
        env = marl_cover.parallel_env(
            graph=line, num_robots=len(team), hops=3, observation_mode="compact"
        )
        obs, _ = env.reset(seed=0, options={"robot_nodes": team, "interest_nodes": [4, 30]})
        views.append(obs["robot_0"])
    for view in views[1:]:
        for a, b in zip(view["graph"], views[0]["graph"], strict=True):
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("hops", [5, 19])
def test_padded_size_stops_growing_once_the_team_outnumbers_the_ball(hops: int) -> None:
    sizes = {}
    for num_robots in (4, 100, 1000):
        env = marl_cover.parallel_env(
            map="city", city_size=60_000, num_robots=num_robots, hops=hops
        )
        sizes[num_robots] = env.observation_bytes_bound() // num_robots
    ball = 2 * hops * hops + 2 * hops + 1
    assert sizes[4] < sizes[100] if hops == 5 else sizes[4] < sizes[100] < sizes[1000]
    if ball < 100:
        assert sizes[100] == sizes[1000]
    compact = marl_cover.parallel_env(
        map="city", city_size=60_000, num_robots=1000, hops=hops, observation_mode="compact"
    )
    # the compact worst case per robot is the padded bound without padding, team-independent
    assert compact.observation_bytes_bound() // 1000 < sizes[1000]


def test_memory_limit_is_checked_before_anything_is_allocated() -> None:
    with pytest.raises(ValueError, match=r"1000 robots .* MiB .*max_observation_bytes=1048576"):
        marl_cover.parallel_env(
            map="city", city_size=60_000, num_robots=1000, max_observation_bytes=2**20
        )
    env = marl_cover.parallel_env(
        map="city", city_size=60_000, num_robots=1000, max_observation_bytes=None
    )
    assert env.observation_bytes_bound() > 2**20


def test_a_team_larger_than_the_city_names_both_numbers() -> None:
    with pytest.raises(ValueError, match="1000 robots do not fit on maps of 500 waypoints"):
        marl_cover.parallel_env(map="city", city_size=500, num_robots=1000)


def test_kernel_scratch_must_match_the_map(path_graph, tee_graph) -> None:
    pytest.importorskip("numba")
    from marl_cover.ego import ego_shape

    shape = ego_shape(8, 1, 2, True)
    features = np.zeros((8, 4), dtype=np.float32)
    with pytest.raises(ValueError, match="made for 6 waypoints, the map has 8"):
        build_ego_graphs(
            path_graph, np.array([0]), features, 2, shape, "numba", scratch=EgoScratch(tee_graph)
        )


def test_tables_give_the_action_edges_and_a_flat_graph(path_graph) -> None:
    env = marl_cover.parallel_env(
        graph=path_graph, num_robots=2, hops=2, observation_mode="compact"
    )
    env.reset(seed=0, options={"robot_nodes": [0, 2]})
    tables: CompactObservations = env.observe_compact()
    # robot 0: stay, east; robot 1 (waypoint 2): stay, east, west
    np.testing.assert_array_equal(tables.action_edges(), [[0, 1, -1, -1, -1], [12, 13, -1, 14, -1]])
    _, edge_index, _ = tables.flat_graph()
    first = tables.node_offsets[1]
    # its stay edge: waypoint 2, local node 3 of the ball 0..4, into the robot (local node 0)
    np.testing.assert_array_equal(edge_index[:, 12], [first + 3, first])


def test_a_thousand_robots_for_twenty_steps() -> None:
    """1000 robots on a 56,590-waypoint procedural city, random legal moves: nobody ever
    shares a waypoint, and the team's reward is the golden one of this seed."""
    env = marl_cover.parallel_env(
        map="city",
        city_size=56_590,
        num_robots=1000,
        hops=5,
        max_steps=20,
        observation_mode="compact",
    )
    obs, _ = env.reset(seed=7)
    rng = np.random.default_rng(7)
    total, steps = 0.0, 0
    while env.agents:
        masks = np.stack([obs[a]["action_mask"] for a in env.agents])  # (1000, 5)
        actions = np.argmax(rng.random(masks.shape) * masks, axis=1)  # a random legal move
        obs, rewards, *_ = env.step(dict(zip(env.agents, actions.tolist(), strict=True)))
        assert len(np.unique(env.snapshot().robot_node)) == 1000
        total += rewards["robot_0"]
        steps += 1
    assert steps == 20
    assert total == GOLDEN_THOUSAND


#: The team reward of the episode above (seed 7).
GOLDEN_THOUSAND = 1566.0


def test_observations_kept_by_the_user_are_never_overwritten() -> None:
    """The builder reuses the tables of a step whose observations nobody holds any more; the
    ones a caller keeps stay as they were, whatever the steps after them."""
    env = marl_cover.parallel_env(num_robots=8, hops=4, city_size=300, observation_mode="compact")
    obs, _ = env.reset(seed=1)
    kept = [(obs, {a: [np.copy(x) for x in o["graph"]] for a, o in obs.items()})]
    rng = np.random.default_rng(1)
    for step in range(12):
        obs, *_ = env.step({a: int(rng.integers(5)) for a in env.agents})
        if step % 4 == 0:
            kept.append((obs, {a: [np.copy(x) for x in o["graph"]] for a, o in obs.items()}))
        tables = env.observe_compact()  # dropped at once: its buffers come back to the pool
        del tables
    for observations, copies in kept:
        for agent, arrays in copies.items():
            for now, then in zip(observations[agent]["graph"], arrays, strict=True):
                np.testing.assert_array_equal(now, then)


def test_padded_observations_kept_by_the_user_are_never_overwritten() -> None:
    """Padded arrays are refilled only when nobody holds them; a refilled set equals a fresh
    build (the kernel clears exactly what it wrote before)."""
    pytest.importorskip("numba")
    env = marl_cover.parallel_env(num_robots=8, hops=4, city_size=300)
    obs, _ = env.reset(seed=2)
    kept = [(obs, {a: {k: np.copy(v) for k, v in o.items()} for a, o in obs.items()})]
    rng = np.random.default_rng(2)
    for step in range(12):
        obs, *_ = env.step({a: int(rng.integers(5)) for a in env.agents})
        if step % 4 == 0:
            kept.append((obs, {a: {k: np.copy(v) for k, v in o.items()} for a, o in obs.items()}))
        reused = env.observe_batch()  # from the pool once the step's own set is dropped
        fresh = build_ego_graphs(
            env._graph, env.snapshot().robot_node, env._waypoint_features, 4, env.padded_shape
        )
        for key, value in fresh.items():
            np.testing.assert_array_equal(reused[key], value, err_msg=key)
        del reused
    for observations, copies in kept:
        for agent, arrays in copies.items():
            for key, value in arrays.items():
                np.testing.assert_array_equal(observations[agent][key], value)
