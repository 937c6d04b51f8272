"""Ego-graphs against a networkx reference, and the message-passing equivalence they promise."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest
from helpers import random_grid_graph, run_cli

import marl_cover
from marl_cover.ego import NUM_ACTIONS, action_targets


def reference_graph(env) -> nx.Graph:
    """The whole robot + waypoint graph, nodes named ('w', i) and ('r', j)."""
    snap = env.snapshot()
    graph = nx.Graph()
    for w in range(snap.graph.num_nodes):
        graph.add_node(("w", w))
    for s, r in snap.graph.edge_index.T.tolist():
        graph.add_edge(("w", s), ("w", r))
    for j, targets in enumerate(action_targets(snap.graph, snap.robot_node).tolist()):
        for t in targets:
            if t >= 0:
                graph.add_edge(("r", j), ("w", t))
    return graph


def named_ego(obs: dict[str, np.ndarray], snap, ego: int) -> nx.Graph:
    """An observation's graph with nodes renamed to global names, via the documented order."""
    mask = obs["node_mask"]
    nodes = obs["nodes"]
    count = int(mask.sum())
    num_waypoints = int(nodes[:count, 1].sum())
    origin = snap.graph.positions[snap.robot_node[ego]] / snap.graph.cell_size
    cells = snap.graph.positions / snap.graph.cell_size
    names = {0: ("r", ego)}
    for local in range(1, 1 + num_waypoints):  # waypoints in increasing map index
        w = int(
            np.flatnonzero(np.all(np.isclose(cells - origin, obs["node_pos"][local]), axis=1))[0]
        )
        names[local] = ("w", w)
    others = [j for j in range(len(snap.robot_node)) if j != ego]
    robot_locals = range(1 + num_waypoints, count)
    in_ball = [j for j in others if ("w", int(snap.robot_node[j])) in names.values()]
    for local, j in zip(robot_locals, in_ball, strict=False):
        names[local] = ("r", j)
    graph = nx.Graph()
    graph.add_nodes_from(names.values())
    for s, r in obs["edge_index"][:, obs["edge_mask"]].T.tolist():
        graph.add_edge(names[s], names[r])
    return graph


@pytest.mark.parametrize("seed", range(6))
def test_ego_graph_is_the_induced_k_hop_ball(seed: int) -> None:
    rng = np.random.default_rng(seed)
    graph = random_grid_graph(rng, 12, 14, 0.75)
    hops = int(rng.integers(1, 7))
    num_robots = int(rng.integers(1, min(8, graph.num_nodes)))
    env = marl_cover.parallel_env(graph=graph, num_robots=num_robots, hops=hops)
    obs, _ = env.reset(seed=seed)
    for _ in range(3):
        snap = env.snapshot()
        whole = reference_graph(env)
        for j, agent in enumerate(env.possible_agents):
            expected = nx.ego_graph(whole, ("r", j), radius=hops)
            got = named_ego(obs[agent], snap, j)
            assert set(got.nodes) == set(expected.nodes)
            assert set(map(frozenset, got.edges)) == set(map(frozenset, expected.edges))
            # edges are stored once per direction
            assert obs[agent]["edge_mask"].sum() == 2 * expected.number_of_edges()
            assert env.observation_space(agent).contains(obs[agent])
            # every entry is an array of its space's shape (no numpy scalars to cast)
            for key, value in obs[agent].items():
                assert isinstance(value, np.ndarray), key
                assert value.shape == env.observation_space(agent)[key].shape, key
        obs, *_ = env.step({a: int(rng.integers(NUM_ACTIONS)) for a in env.agents})


def mean_message_passing(nodes, edge_index, edge_mask, weights):
    """K layers of h <- tanh(W [h, mean of in-neighbours' h]) on one padded graph."""
    h = nodes.astype(np.float64)
    senders, receivers = edge_index[:, edge_mask]
    degree = np.bincount(receivers, minlength=len(h))[:, None]
    for w in weights:
        total = np.zeros_like(h)
        np.add.at(total, receivers, h[senders])
        h = np.tanh(np.concatenate([h, total / np.maximum(degree, 1)], axis=1) @ w)
    return h


@pytest.mark.parametrize("hops", [1, 3, 6])
def test_k_layers_on_ego_graph_equal_k_layers_on_the_state(hops: int) -> None:
    rng = np.random.default_rng(hops)
    graph = random_grid_graph(rng, 14, 14, 0.8)
    env = marl_cover.parallel_env(graph=graph, num_robots=6, hops=hops)
    obs, _ = env.reset(seed=hops)
    obs, *_ = env.step({a: 1 for a in env.agents})
    weights = [rng.normal(size=(8, 4)) for _ in range(hops)]
    state = env.state()
    whole = mean_message_passing(state["nodes"], state["edge_index"], state["edge_mask"], weights)
    for j, agent in enumerate(env.possible_agents):
        o = obs[agent]
        ego = mean_message_passing(o["nodes"], o["edge_index"], o["edge_mask"], weights)
        np.testing.assert_allclose(ego[0], whole[state["robot_nodes"][j]], atol=1e-9)


@pytest.mark.parametrize("seed", range(8))
def test_numba_and_numpy_backends_agree(seed: int) -> None:
    pytest.importorskip("numba")
    from marl_cover.ego import build_ego_graphs

    rng = np.random.default_rng(100 + seed)
    graph = random_grid_graph(rng, 15, 15, 0.8)
    hops = int(rng.integers(1, 9))
    env = marl_cover.parallel_env(graph=graph, num_robots=int(rng.integers(1, 9)), hops=hops)
    env.reset(seed=seed)
    for _ in range(4):
        args = (env._graph, env.snapshot().robot_node, env._waypoint_features, hops, env._ego_shape)
        fast, reference = build_ego_graphs(*args, "numba"), build_ego_graphs(*args, "numpy")
        for key, value in reference.items():
            assert fast[key].dtype == value.dtype, key
            np.testing.assert_array_equal(fast[key], value, err_msg=key)
        env.step({a: int(rng.integers(NUM_ACTIONS)) for a in env.agents})


def test_inspect_ego_script_draws_one_robots_view(tmp_path) -> None:
    pytest.importorskip("matplotlib")
    pytest.importorskip("networkx")
    out = tmp_path / "ego.png"
    done = run_cli("inspect", "env.hops=4", "robot=1", "steps=2", f"out={out}")
    assert done.returncode == 0, done.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for args, message in (
        (["seed=-1"], "seed and steps must be >= 0"),
        (["robot=4"], "robot must be in [0, 4), got 4"),
        (["env.map=nowhere.npy"], "nowhere.npy: occupancy grid not found"),
    ):
        refused = run_cli("inspect", *args, f"out={out}")
        assert refused.returncode != 0 and message in refused.stderr
        assert "Traceback" not in refused.stderr
