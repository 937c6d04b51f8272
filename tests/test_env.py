"""The coverage environment on tiny hand-built graphs: exact observations, rewards, rules."""

from __future__ import annotations

import re

import numpy as np
import pytest
from helpers import random_grid_graph
from hypothesis import given, settings
from hypothesis import strategies as st

import marl_cover
from marl_cover.config import CoverageConfig
from marl_cover.graph import SpatialGraph

SINK = -1  # the last padded node


def real_edges(obs: dict[str, np.ndarray]) -> list[tuple[int, int]]:
    return [tuple(e) for e in obs["edge_index"][:, obs["edge_mask"]].T.tolist()]


def make(graph: SpatialGraph, robots: list[int], interest: list[int], **config):
    env = marl_cover.parallel_env(graph=graph, num_robots=len(robots), **config)
    obs, infos = env.reset(seed=0, options={"robot_nodes": robots, "interest_nodes": interest})
    return env, obs, infos


def test_ego_graph_exact(tee_graph: SpatialGraph) -> None:
    env, obs, _ = make(tee_graph, [0, 3], [2, 5], hops=2)
    o = obs["robot_0"]
    m = o["nodes"].shape[0]
    # node 0 = ego robot; waypoints within 2 hops of waypoint 0: 0, 1, 2, 4 -> local 1..4;
    # robot_1 stands on waypoint 3, three hops away: not in the ego-graph.
    assert o["node_mask"].tolist() == [True] * 5 + [False] * (m - 5)
    assert o["nodes"][:5].tolist() == [
        [1, 0, 0, 0],
        [0, 1, 0, 0],  # waypoint 0 (the robot's own, visited at reset)
        [0, 1, 0, 0],  # waypoint 1
        [0, 1, 1, 0],  # waypoint 2, of interest
        [0, 1, 0, 0],  # waypoint 4
    ]
    assert o["node_pos"][:5].tolist() == [[0, 0], [0, 0], [1, 0], [2, 0], [1, 1]]
    assert o["action_mask"].tolist() == [1, 1, 0, 0, 0]
    sink = m - 1
    assert o["edge_index"][:, :10].T.tolist() == [
        [1, 0],
        [2, 0],
        [sink, sink],
        [sink, sink],
        [sink, sink],
        [0, 1],
        [0, 2],
        [sink, sink],
        [sink, sink],
        [sink, sink],
    ]
    assert real_edges(o) == [
        (1, 0),
        (2, 0),
        (0, 1),
        (0, 2),
        (1, 2),
        (2, 3),
        (2, 4),
        (2, 1),
        (3, 2),
        (4, 2),
    ]
    assert o["edge_attr"][o["edge_mask"], 0].tolist() == [0, 1, 0, 1, 1, 1, 1, 1, 1, 1]
    assert env.observation_space("robot_0").contains(o)


def test_ego_graph_includes_other_robots_and_their_edges(tee_graph: SpatialGraph) -> None:
    _, obs, _ = make(tee_graph, [0, 2], [5], hops=2)
    o = obs["robot_0"]
    # robot_1 on waypoint 2 (two hops) is node 5; its stay (2) and west (1) targets are in the
    # ball, its east target (3) is not.
    assert o["node_mask"].sum() == 6
    assert o["nodes"][5].tolist() == [1, 0, 0, 0]
    assert o["node_pos"][5].tolist() == [2, 0]
    assert real_edges(o)[-4:] == [(3, 5), (5, 3), (2, 5), (5, 2)]
    # robot_1 sees robot_0 too: waypoints 0..4 within two hops of waypoint 2, robot_0 last
    o1 = obs["robot_1"]
    assert o1["node_mask"].sum() == 1 + 5 + 1
    assert o1["action_mask"].tolist() == [1, 1, 0, 1, 0]


def test_hops_one_has_no_other_robots(tee_graph: SpatialGraph) -> None:
    _, obs, _ = make(tee_graph, [1, 2], [5], hops=1)
    o = obs["robot_0"]
    assert o["node_mask"].sum() == 1 + 4  # waypoints 0, 1, 2, 4; robot_1 is two hops away
    assert o["nodes"][:5, 0].tolist() == [1, 0, 0, 0, 0]


def test_rewards_infos_and_termination(path_graph: SpatialGraph) -> None:
    env, obs, infos = make(path_graph, [0, 7], [1, 2, 6], max_steps=10)
    assert infos["robot_0"] == {
        "new_interest": 0,
        "total_interest": 0,
        "blocked": False,
        "invalid_action": False,
    }
    east, west = 1, 3
    obs, rew, term, trunc, infos = env.step({"robot_0": east, "robot_1": west})
    assert rew == {"robot_0": 2.0, "robot_1": 2.0}
    assert infos["robot_0"]["new_interest"] == 1 and infos["robot_1"]["new_interest"] == 1
    assert not any(term.values()) and not any(trunc.values())
    obs, rew, term, trunc, infos = env.step({"robot_0": east, "robot_1": west})
    assert rew["robot_0"] == 1.0  # robot_0 reaches 2, robot_1 reaches 5 (not of interest)
    assert all(term.values()) and not any(trunc.values())
    assert infos["robot_0"]["total_interest"] == 2 and infos["robot_1"]["total_interest"] == 1
    assert env.agents == []
    with pytest.raises(RuntimeError, match="reset"):
        env.step({})


def test_truncation_after_exactly_max_steps(path_graph: SpatialGraph) -> None:
    env, *_ = make(path_graph, [3], [0, 7], max_steps=4)
    for step in range(4):
        assert env.agents == ["robot_0"]
        _, rew, term, trunc, _ = env.step({"robot_0": 0})
        assert rew["robot_0"] == 0.0 and not term["robot_0"]
        assert trunc["robot_0"] == (step == 3)
    assert env.agents == []


def test_revisits_and_collisions_pay_nothing(path_graph: SpatialGraph) -> None:
    env, *_ = make(path_graph, [2, 4], [3, 5])
    # both head for waypoint 3: robot_0 (lower index) gets it, robot_1 is blocked
    _, rew, _, _, infos = env.step({"robot_0": 1, "robot_1": 3})
    assert rew["robot_0"] == 1.0
    assert infos["robot_0"]["blocked"] is False and infos["robot_1"]["blocked"] is True
    assert env.snapshot().robot_node.tolist() == [3, 4]
    _, rew, _, _, _ = env.step({"robot_0": 3, "robot_1": 3})  # back to 2, and into 3
    assert rew["robot_0"] == 0.0
    assert env.snapshot().robot_node.tolist() == [2, 3]


def test_masked_action_is_a_counted_noop(path_graph: SpatialGraph) -> None:
    env, *_ = make(path_graph, [0], [5])
    north = 2
    _, rew, _, _, infos = env.step({"robot_0": north})
    assert infos["robot_0"]["invalid_action"] is True
    assert env.snapshot().robot_node.tolist() == [0]


def test_masked_action_can_raise(path_graph: SpatialGraph) -> None:
    env, *_ = make(path_graph, [0, 5], [5], invalid_action="raise")
    with pytest.raises(ValueError, match="robot_1"):
        env.step({"robot_0": 0, "robot_1": 4})


@pytest.mark.parametrize(
    ("actions", "message"),
    [
        ({"robot_0": 0}, "no action given for \\['robot_1'\\]"),
        ({"robot_0": 0, "robot_1": 0, "robot_9": 0}, "unknown agents \\['robot_9'\\]"),
        ({"robot_0": 0, "robot_1": 7}, "action of robot_1"),
        ({"robot_0": 1.5, "robot_1": 0}, "action of robot_0"),
        ({"robot_0": 0, "robot_1": "x"}, "action of robot_1 .* got 'x'"),
        ({"robot_0": True, "robot_1": 0}, "action of robot_0 .* got True"),
        ({"robot_0": np.array([1]), "robot_1": 0}, "action of robot_0"),
        ({"robot_9": 0}, "unknown agents \\['robot_9'\\]; the agents are"),  # typo before gaps
    ],
)
def test_bad_actions_name_the_robot(path_graph: SpatialGraph, actions, message) -> None:
    env, *_ = make(path_graph, [0, 5], [5])
    with pytest.raises(ValueError, match=message):
        env.step(actions)


def test_integer_actions_of_any_numeric_type(path_graph: SpatialGraph) -> None:
    """Python, numpy (scalar and 0-d) and integral floats are the same action."""
    positions = []
    for action in (1, np.int64(1), np.array(1), 1.0):  # 1 = east
        env, *_ = make(path_graph, [0, 5], [5])
        env.step({"robot_0": action, "robot_1": 0})
        positions.append(env.snapshot().robot_node.tolist())
    assert positions == [[1, 5]] * 4


@pytest.mark.parametrize("seed", [-1, 1.5, "0"])
def test_reset_rejects_bad_seeds(seed) -> None:
    env = marl_cover.parallel_env()
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        env.reset(seed=seed)


def test_config_errors_name_the_key(path_graph: SpatialGraph) -> None:
    with pytest.raises(TypeError, match="hopz"):
        marl_cover.parallel_env(hopz=3)
    with pytest.raises(TypeError, match="colour"):
        CoverageConfig.from_dict({"colour": 1})
    with pytest.raises(ValueError, match="num_robots"):
        marl_cover.parallel_env(num_robots=0)
    with pytest.raises(ValueError, match="9 robots do not fit"):
        marl_cover.parallel_env(graph=path_graph, num_robots=9)
    with pytest.raises(ValueError, match="neither a preset"):
        marl_cover.parallel_env(map="atlantis")
    with pytest.raises(FileNotFoundError, match="nowhere.npy"):
        marl_cover.parallel_env(map="nowhere.npy")
    with pytest.raises(TypeError, match="not both"):
        marl_cover.parallel_env(max_steps=3, max_cycles=3)
    for kwargs, message in (
        ({"map_cell_size": -1.0}, "map_cell_size must be > 0 metres, got -1.0"),
        ({"map_perimeter": -5.0}, "map_perimeter must be >= 0 cells or null, got -5.0"),
        ({"min_window_nodes": 0}, "min_window_nodes must be >= 1, got 0"),
        ({"start_density": 0}, "start_density must be >= 1, got 0"),
    ):
        with pytest.raises(ValueError, match=message):
            CoverageConfig(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"num_robots": "4"}, "CoverageConfig.num_robots must be an integer, got '4'"),
        ({"hops": 2.5}, "CoverageConfig.hops must be an integer, got 2.5"),
        ({"allow_swaps": 1}, "CoverageConfig.allow_swaps must be true or false, got 1"),
        ({"window_fraction": "x"}, "CoverageConfig.window_fraction must be a number or None"),
        ({"map": 3}, "CoverageConfig.map must be a string, got 3"),
    ],
)
def test_config_values_of_the_wrong_type_name_the_key(kwargs, message) -> None:
    with pytest.raises(TypeError, match=re.escape(message)):
        marl_cover.parallel_env(**kwargs)


def test_config_accepts_numpy_numbers_and_paths(tmp_path) -> None:
    config = CoverageConfig(num_robots=np.int64(3), sensor_range=np.float32(20), max_steps=7)
    assert config.num_robots == 3 and config.interest_fraction == 0.5
    assert CoverageConfig(map=tmp_path / "grid.npy").map == str(tmp_path / "grid.npy")


def test_reset_draws_paper_defaults() -> None:
    env = marl_cover.parallel_env(num_robots=4, city_size=300)
    env.reset(seed=5)
    snap = env.snapshot()
    assert snap.interest.sum() == 150
    assert len(np.unique(snap.robot_node)) == 4
    assert snap.visited.sum() == 4 and snap.visited[snap.robot_node].all()
    # start waypoints lie in a breadth-first ball of >= 20 waypoints: within a few hops
    dist = snap.graph.hop_distances(snap.robot_node[:1])[0]
    assert dist[snap.robot_node].max() <= 8


def run_episode(env, seed: int, steps: int, action_seed: int):
    rng = np.random.default_rng(action_seed)
    obs, _ = env.reset(seed=seed)
    trace = [obs]
    for _ in range(steps):
        if not env.agents:
            obs, _ = env.reset()
        actions = {a: int(rng.integers(5)) for a in env.agents}
        trace.append(env.step(actions))
    return trace


def assert_same(a, b) -> None:
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            assert_same(a[key], b[key])
    elif isinstance(a, (tuple, list)):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            assert_same(x, y)
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    else:
        assert a == b


@pytest.mark.parametrize("map_name", ["city", "paper"])
def test_same_seed_same_episode_over_100_steps(map_name: str, request) -> None:
    if map_name == "paper":
        request.getfixturevalue("paper_map_available")
    config = {"map": map_name, "hops": 5, "max_steps": 100}
    first = run_episode(marl_cover.parallel_env(**config), 11, 100, 3)
    second = run_episode(marl_cover.parallel_env(**config), 11, 100, 3)
    assert_same(first, second)
    other = run_episode(marl_cover.parallel_env(**config), 12, 100, 3)
    assert not np.array_equal(first[0]["robot_0"]["nodes"], other[0]["robot_0"]["nodes"])


def test_state_encodes_the_whole_graph(tee_graph: SpatialGraph) -> None:
    env, *_ = make(tee_graph, [0, 2], [5])
    state = env.state()
    assert env.state_space.contains(state)
    assert state["robot_nodes"].tolist() == [0, 1]
    assert state["node_mask"].sum() == 2 + 6
    assert state["nodes"][:8, :3].tolist() == [
        [1, 0, 0],
        [1, 0, 0],
        [0, 1, 0],
        [0, 1, 0],
        [0, 1, 0],
        [0, 1, 0],
        [0, 1, 0],
        [0, 1, 1],
    ]
    sink = state["nodes"].shape[0] - 1
    # action edges in: robot r slot k at 5 r + k; waypoint w is node 2 + w
    assert state["edge_index"][:, :10].T.tolist() == [
        [2, 0],
        [3, 0],
        [sink, sink],
        [sink, sink],
        [sink, sink],
        [4, 1],
        [5, 1],
        [sink, sink],
        [3, 1],
        [sink, sink],
    ]
    assert state["action_mask"].tolist() == [[1, 1, 0, 0, 0], [1, 1, 0, 1, 0]]
    assert state["edge_mask"].sum() == 2 * (2 + 3) + tee_graph.num_edges


def test_registered_ids() -> None:
    import pettingzoo

    env = pettingzoo.make("parallel", "marl_cover/Coverage-v0", num_robots=2, hops=3)
    assert env.possible_agents == ["robot_0", "robot_1"]
    aec = pettingzoo.make("aec", "marl_cover/Coverage-v0", num_robots=2, hops=3)
    aec.reset(seed=0)
    assert aec.agent_selection == "robot_0"


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    num_robots=st.integers(1, 12),
    allow_swaps=st.booleans(),
    actions=st.lists(
        st.lists(st.integers(0, 4), min_size=12, max_size=12), min_size=1, max_size=15
    ),
)
def test_robots_never_share_a_waypoint(seed, num_robots, allow_swaps, actions) -> None:
    graph = random_grid_graph(np.random.default_rng(seed), 6, 7, 0.85)
    num_robots = min(num_robots, graph.num_nodes)
    env = marl_cover.parallel_env(
        graph=graph, num_robots=num_robots, hops=3, allow_swaps=allow_swaps
    )
    env.reset(seed=seed)
    for row in actions:
        before = env.snapshot().robot_node
        _, _, _, _, infos = env.step({a: row[i] for i, a in enumerate(env.possible_agents)})
        after = env.snapshot().robot_node
        assert len(np.unique(after)) == num_robots
        # a robot that moved went along one edge, and a blocked robot stayed
        for i in np.flatnonzero(after != before):
            assert after[i] in graph.neighbors[before[i]]
        for i, agent in enumerate(env.possible_agents):
            if infos[agent]["blocked"]:
                assert after[i] == before[i]
        if not env.agents:
            break


@pytest.mark.parametrize("task", ["coverage", "exploration"])
def test_a_fork_plays_the_same_future_and_leaves_the_original_alone(task: str) -> None:
    env = marl_cover.parallel_env(task=task, num_robots=3, hops=3, max_steps=12, city_size=200)
    env.reset(seed=2)
    rng = np.random.default_rng(0)

    def random_moves(mask: np.ndarray) -> np.ndarray:
        return np.array([rng.choice(np.flatnonzero(row)) for row in mask])

    for _ in range(3):
        env.apply_actions(random_moves(env.state()["action_mask"]))
    before = env.state()
    fork = env.fork()
    assert fork.snapshot().graph is env.snapshot().graph and fork.config is env.config
    moves, rewards = [], []
    while fork.agents:
        moves.append(random_moves(fork.state()["action_mask"]))
        rewards.append(fork.apply_actions(moves[-1]).new_interest.tolist())
    assert sum(map(sum, rewards)) > 0 and not fork.agents and env.agents
    for key, value in before.items():
        np.testing.assert_array_equal(env.state()[key], value)
    # the original then plays the fork's moves and gets the fork's rewards
    assert [env.apply_actions(m).new_interest.tolist() for m in moves] == rewards
    assert not env.agents


def test_a_fork_draws_with_a_renderer_of_its_own() -> None:
    pytest.importorskip("matplotlib")
    env = marl_cover.parallel_env(num_robots=2, hops=3, city_size=100, render_mode="rgb_array")
    env.reset(seed=0)
    image = env.render()
    fork = env.fork()
    np.testing.assert_array_equal(fork.render(), image)
    fork.close()
    np.testing.assert_array_equal(env.render(), image)  # the original's renderer still draws
