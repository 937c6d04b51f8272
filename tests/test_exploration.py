"""Exploration: sensing, the known graph, frontier flags, masking, baselines, checkers."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from helpers import random_grid_graph
from hypothesis import given, settings
from hypothesis import strategies as st
from pettingzoo.test import parallel_api_test, parallel_seed_test

import marl_cover
from marl_cover.discovery import Discovery, frontier_of, known_neighbors, sensor_footprints
from marl_cover.ego import build_ego_graphs
from marl_cover.graph import SpatialGraph

SMALL = {"task": "exploration", "city_size": 120, "hops": 4}


@pytest.fixture
def u_graph() -> SpatialGraph:
    """A U of seven waypoints, cell size 5 m; the arms 0 and 6 are 10 m apart::

    6 - 5 - 4
            |
            3
            |
    0 - 1 - 2
    """
    positions = np.array([(0, 0), (5, 0), (10, 0), (10, 5), (10, 10), (5, 10), (0, 10)], float)
    edges = [(i, i + 1) for i in range(6)]
    return SpatialGraph.from_edges(positions, edges, cell_size=5.0)


def explore(graph: SpatialGraph, robots: list[int], interest: list[int], **config):  # noqa: ANN201
    env = marl_cover.parallel_env(graph=graph, task="exploration", num_robots=len(robots), **config)
    observations, _ = env.reset(seed=0, options={"robot_nodes": robots, "interest_nodes": interest})
    return env, observations


def test_sensing_on_a_path_step_by_step(path_graph: SpatialGraph) -> None:
    """8 waypoints 5 m apart; a 12 m sensor sees its own waypoint and two on each side."""
    env, _ = explore(path_graph, [0], [7], sensor_range=12.0, hops=3)
    expected = [[0, 1, 2], [0, 1, 2, 3], [0, 1, 2, 3, 4], [0, 1, 2, 3, 4]]
    for t, nodes in enumerate(expected):
        snap = env.snapshot()
        assert np.flatnonzero(snap.discovered).tolist() == nodes, f"step {t}"
        assert np.flatnonzero(snap.frontier).tolist() == [max(nodes)], f"step {t}"
        env.step({"robot_0": 1 if t < 2 else 3})  # east, east, then west: nothing new
    env.step({"robot_0": 1})


def test_range_is_euclidean_and_the_known_graph_keeps_only_known_edges(u_graph) -> None:  # noqa: ANN001
    env, observations = explore(u_graph, [0], [4, 6], sensor_range=12.0, hops=8)
    snap = env.snapshot()
    # 3 and 5 are 11.2 m away, 6 is 10 m away across the gap, 4 is 14.1 m away
    assert np.flatnonzero(snap.discovered).tolist() == [0, 1, 2, 3, 5, 6]
    assert np.flatnonzero(snap.frontier).tolist() == [3, 5]
    known = snap.known()
    assert known.graph.neighbors.tolist() == [
        [1, -1, -1, -1],
        [2, -1, 0, -1],
        [-1, 3, 1, -1],
        [-1, -1, -1, 2],
        [-1, -1, -1, -1],
        [-1, -1, 6, -1],
        [5, -1, -1, -1],
    ]
    assert np.flatnonzero(known.interest).tolist() == [6]  # 4 is not discovered
    # the ego-graph is the known graph within 8 hops: 5 and 6 are known but out of reach
    obs = observations["robot_0"]
    count = int(obs["node_mask"].sum())
    assert count == 5
    assert obs["node_pos"][1:count].tolist() == [[0, 0], [1, 0], [2, 0], [2, 1]]
    assert obs["nodes"][1:count, 3].tolist() == [0, 0, 0, 1]  # frontier: waypoint 3
    assert obs["nodes"][1:count, 2].tolist() == [0, 0, 0, 0]
    assert int(obs["edge_mask"].sum()) == 2 * 2 + 6  # stay and east both ways; 3 lattice edges
    # the state holds every discovered waypoint (in discovery order) and only known edges
    state = env.state()
    assert int(state["node_mask"].sum()) == 1 + 6
    assert state["node_pos"][1:7].tolist() == [[0, 0], [1, 0], [2, 0], [2, 1], [1, 2], [0, 2]]
    assert state["nodes"][1:7, 2].tolist() == [0, 0, 0, 0, 0, 1]  # 6 is a point of interest
    assert state["nodes"][1:7, 3].tolist() == [0, 0, 0, 1, 1, 0]
    waypoint_edges = state["edge_index"][:, 10:][:, state["edge_mask"][10:]] - 1
    assert sorted(map(tuple, waypoint_edges.T.tolist())) == [
        (0, 1), (1, 0), (1, 2), (2, 1), (2, 3), (3, 2), (4, 5), (5, 4)
    ]  # fmt: skip
    # walking north from 2 reveals 4 and joins the two arms
    env.step({"robot_0": 1})
    env.step({"robot_0": 1})
    snap = env.snapshot()
    assert snap.discovered.all() and not snap.frontier.any()
    assert np.array_equal(snap.known().graph.neighbors, u_graph.neighbors)
    assert int(env.state()["edge_mask"][10:].sum()) == 12


def test_coverage_is_exploration_with_everything_known(u_graph) -> None:  # noqa: ANN001
    coverage = marl_cover.parallel_env(graph=u_graph, num_robots=1, hops=8)
    observations, _ = coverage.reset(options={"robot_nodes": [0], "interest_nodes": [3, 4]})
    wide, _ = explore(u_graph, [0], [3, 4], sensor_range=100.0, hops=8)
    snap = wide.snapshot()
    assert snap.discovered.all() and not snap.frontier.any()
    assert coverage.snapshot().discovered.all()
    for key, value in observations["robot_0"].items():
        np.testing.assert_array_equal(value, wide.observe_batch()[key][0], err_msg=key)


def test_sensor_shorter_than_an_edge_is_an_error(path_graph: SpatialGraph) -> None:
    env = marl_cover.parallel_env(graph=path_graph, task="exploration", sensor_range=4.0)
    with pytest.raises(ValueError, match="sensor_range 4.0 m is shorter than the longest edge"):
        env.reset(seed=0)
    with pytest.raises(ValueError, match="task must be one of"):
        marl_cover.parallel_env(task="explore")


def test_incremental_discovery_equals_a_rebuild() -> None:
    graph = random_grid_graph(np.random.default_rng(4), 12, 14, 0.3)
    footprint = sensor_footprints(graph, 12.0)
    discovery = Discovery(graph, footprint)
    rng = np.random.default_rng(0)
    for _ in range(20):
        robots = rng.choice(graph.num_nodes, size=3, replace=False)
        discovery.sense(robots)
        discovered = discovery.discovered
        np.testing.assert_array_equal(discovery.neighbors, known_neighbors(graph, discovered))
        np.testing.assert_array_equal(discovery.frontier, frontier_of(graph, discovered))
        assert sorted(discovery.order.tolist()) == np.flatnonzero(discovered).tolist()
        edges = discovery.order[discovery.edge_index]  # back to waypoint indices
        expected = known_neighbors(graph, discovered)
        senders, slots = np.nonzero(expected >= 0)
        assert sorted(map(tuple, edges.T.tolist())) == sorted(
            zip(senders.tolist(), expected[senders, slots].tolist(), strict=True)
        )
        assert len(np.unique(edges, axis=1).T) == discovery.num_known_edges


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), num_robots=st.integers(1, 6), hops=st.integers(1, 6))
def test_undiscovered_waypoints_never_appear(seed: int, num_robots: int, hops: int) -> None:
    """Property: over random episodes, every waypoint in any observation or in ``state()`` is
    discovered, the state holds all of them, and both ego-graph backends agree."""
    graph = random_grid_graph(np.random.default_rng(seed), 9, 11, 0.35)
    num_robots = min(num_robots, graph.num_nodes)
    env = marl_cover.parallel_env(
        graph=graph, task="exploration", num_robots=num_robots, hops=hops, max_steps=12
    )

    def keys(cells: np.ndarray) -> list[tuple[int, int]]:  # cells are on a half-cell grid
        return [tuple(c) for c in (2 * cells).round().astype(int).tolist()]

    cell_index = {key: i for i, key in enumerate(keys(graph.float_cells))}
    rng = np.random.default_rng(seed)
    observations, _ = env.reset(seed=seed)
    while True:
        snap = env.snapshot()
        discovered = snap.discovered
        batch = env.observe_batch()
        numpy = build_ego_graphs(
            graph,
            snap.robot_node,
            env._waypoint_features,
            hops,
            env._ego_shape,
            "numpy",
            known_neighbors(graph, discovered),
        )
        assert set(batch) == {*numpy, "steps_left"}
        for key in numpy:
            np.testing.assert_array_equal(batch[key], numpy[key], err_msg=key)
        for i, agent in enumerate(env.possible_agents):
            obs = observations[agent]
            real = obs["node_mask"] & (obs["nodes"][:, 1] > 0)
            origin = graph.float_cells[snap.robot_node[i]]
            ids = [cell_index[key] for key in keys(obs["node_pos"][real] + origin)]
            assert discovered[ids].all()
            assert (obs["nodes"][real, 3] > 0).tolist() == snap.frontier[ids].tolist()
        state = env.state()
        waypoints = state["node_mask"] & (state["nodes"][:, 1] > 0)
        ids = [cell_index[key] for key in keys(state["node_pos"][waypoints])]
        assert sorted(ids) == np.flatnonzero(discovered).tolist()
        assert (state["nodes"][waypoints, 3] > 0).tolist() == snap.frontier[ids].tolist()
        if not env.agents:
            break
        actions = {a: int(rng.integers(5)) for a in env.agents}
        observations, *_ = env.step(actions)


def test_same_seed_same_exploration_episode() -> None:
    def play(seed: int) -> list:
        env = marl_cover.parallel_env(**SMALL)
        env.reset(seed=seed)
        rng = np.random.default_rng(1)
        trace = []
        while env.agents:
            observations, rewards, *_ = env.step({a: int(rng.integers(5)) for a in env.agents})
            trace.append((env.snapshot().discovered.tobytes(), rewards["robot_0"]))
        return trace

    assert play(3) == play(3)


def test_greedy_heads_for_the_frontier(u_graph) -> None:  # noqa: ANN001
    from marl_cover.agents.baselines.greedy import CentralizedGreedyPolicy, GreedyPolicy

    env, observations = explore(u_graph, [0], [], sensor_range=12.0, hops=8)
    assert GreedyPolicy(8).act(observations) == {"robot_0": 1}  # east, toward frontier 3
    assert CentralizedGreedyPolicy(8).act(env.state(), ["robot_0"]) == {"robot_0": 1}
    coverage = marl_cover.parallel_env(graph=u_graph, num_robots=1, hops=8)
    observations, _ = coverage.reset(options={"robot_nodes": [0], "interest_nodes": []})
    assert GreedyPolicy(8).act(observations) == {"robot_0": 0}  # nothing to go for


@pytest.mark.filterwarnings("ignore:reset ignores unknown option")
def test_pettingzoo_checkers_on_exploration() -> None:
    parallel_api_test(marl_cover.parallel_env(**SMALL), num_cycles=60)
    parallel_seed_test(functools.partial(marl_cover.parallel_env, **SMALL), num_cycles=30)


def test_fair_expert_ignores_what_is_not_discovered(u_graph) -> None:  # noqa: ANN001
    """The fair expert acts the same whatever lies in the unknown; the omniscient one goes for
    an undiscovered point of interest."""
    pytest.importorskip("pyvrp")
    from marl_cover.agents.experts import RoutingExpert

    def first_actions(interest: list[int], information: str, robot: int) -> list[int]:
        env, _ = explore(u_graph, [robot], interest, sensor_range=6.0, hops=8, max_steps=6)
        expert = RoutingExpert(
            mode="receding", horizon=6, information=information, max_iterations=50
        )
        actions = []
        while env.agents:
            chosen = expert.act_env(env)
            actions.append(chosen["robot_0"])
            env.step(chosen)
        return actions

    # robot on 2 with a 6 m sensor: knows 1, 2, 3; frontier 1 (west) and 3 (north)
    fair = first_actions([0], "known", 2)
    assert fair[:2] == [2, 2]  # north: frontier 3, then 4 (tie with west broken by the plan)
    assert fair == first_actions([0, 5], "known", 2)  # 0 and 5 are undiscovered at the start
    assert first_actions([6], "full", 2)[0] == 2  # omniscient: north, toward 6 round the U
    assert first_actions([0], "full", 2)[:2] == [3, 3]  # west twice, to 0


def test_omniscient_expert_plays_the_same_episode_in_both_tasks() -> None:
    """The expert ignores discovery and the environment draws the same episodes, so a
    coverage dataset of the omniscient expert is its exploration dataset."""
    pytest.importorskip("pyvrp")
    from marl_cover.agents.experts import RoutingExpert
    from marl_cover.agents.training.datasets import record_episode

    config = {"map": "city", "city_size": 90, "hops": 5, "max_steps": 15}
    episodes = [
        record_episode(
            marl_cover.parallel_env(task=task, **config), RoutingExpert(max_iterations=100), 7
        )
        for task in ("coverage", "exploration")
    ]
    assert np.array_equal(episodes[0].robot_node, episodes[1].robot_node)
    assert np.array_equal(episodes[0].actions, episodes[1].actions)
    assert np.array_equal(episodes[0].interest, episodes[1].interest)


def test_expected_expert_values_the_unknown_by_the_share_of_points_seen(u_graph) -> None:  # noqa: ANN001
    """The "expected" expert plans on the true map: the discovered points are worth one prize,
    each undiscovered waypoint the share of points of interest among the discovered ones; it
    heads for the larger unknown, where the omniscient expert heads for the hidden point."""
    pytest.importorskip("pyvrp")
    from marl_cover.agents.experts import RoutingExpert, build_problem

    # robot on 2 with a 6 m sensor: knows 1, 2, 3, of which 2 (visited at the start) is a
    # point: share 1/3; 0 (west) is the one point left
    env, _ = explore(u_graph, [2], [0, 2], sensor_range=6.0, hops=8, max_steps=6)
    expert = RoutingExpert(mode="receding", horizon=6, information="expected", max_iterations=50)
    snapshot = env.snapshot()
    value = expert.value(snapshot)
    assert value.tolist() == pytest.approx([1 / 3, 1, 1, 1, 1 / 3, 1 / 3, 1 / 3])
    problem = build_problem(expert.visible(snapshot), 6, value=value)
    assert problem.candidates.tolist() == [0, 4, 5, 6]  # 1, 2 and 3 are known and empty
    assert problem.prizes().tolist() == [3333] * 4
    # north: 4, 5, 6 (1/3 each) beat west to 0 (1/3) and back to 4 in 6 hops (2/3)
    assert expert.act_env(env) == {"robot_0": 2}
    omniscient = RoutingExpert(mode="receding", horizon=6, information="full", max_iterations=50)
    assert omniscient.act_env(env) == {"robot_0": 3}  # west, to the hidden point
    assert RoutingExpert(information="full").value(snapshot) is None


def test_local_expert_sees_the_known_ball_and_the_frontier(u_graph) -> None:  # noqa: ANN001
    pytest.importorskip("pyvrp")
    from marl_cover.agents.experts import LocalRoutingExpert

    # robot on 2 with a 6 m sensor knows 1, 2, 3; the hidden point 0 is no prize, the
    # frontier 1 and 3 (next to 0 and 4) are
    env, _ = explore(u_graph, [2], [0, 2], sensor_range=6.0, hops=8, max_steps=6)
    view = LocalRoutingExpert(6).view(env.snapshot(), 0)
    assert np.flatnonzero(view.discovered).tolist() == [1, 2, 3]
    assert np.flatnonzero(view.unvisited_interest).tolist() == [1, 3]
    assert view.graph.neighbors[[1, 3]].max(axis=1).tolist() == [2, 2]  # no edge to 0 or 4


def test_points_worth_nothing_are_no_candidates(path_graph) -> None:  # noqa: ANN001
    pytest.importorskip("pyvrp")
    from marl_cover.agents.experts import build_problem

    env = marl_cover.parallel_env(graph=path_graph, num_robots=1, hops=7, max_steps=8)
    env.reset(seed=0, options={"robot_nodes": [0], "interest_nodes": [2, 4, 6]})
    value = np.array([1, 1, 0.5, 1, 0.0, 1, 1, 1])
    problem = build_problem(env.snapshot(), 7, value=value)
    assert problem.candidates.tolist() == [2, 6] and problem.prizes().tolist() == [5000, 10000]
    plain = build_problem(env.snapshot(), 7)
    assert plain.candidates.tolist() == [2, 4, 6] and plain.prizes().tolist() == [10000] * 3
