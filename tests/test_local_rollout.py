"""The decentralized rollout (``marl_cover.agents.planners.local_rollout``): the world a robot
builds from its ego-graph, and exact choices of the policy on hand-built graphs."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import marl_cover  # noqa: E402
from marl_cover.agents.models import AggregationGNN, GNNConfig  # noqa: E402
from marl_cover.agents.models.policy import GNNPolicy  # noqa: E402
from marl_cover.agents.planners.local_rollout import LocalRolloutPolicy, ego_world  # noqa: E402
from marl_cover.graph import SpatialGraph  # noqa: E402

STAY, EAST, NORTH, WEST, SOUTH = range(5)


def lattice(width: int, height: int, holes: tuple[tuple[int, int], ...] = ()) -> SpatialGraph:
    """A 4-connected ``width x height`` lattice of 5 m cells without ``holes`` (``(x, y)``);
    waypoints are numbered row by row."""
    cells = [(x, y) for y in range(height) for x in range(width) if (x, y) not in holes]
    index = {cell: i for i, cell in enumerate(cells)}
    edges = [
        (index[(x, y)], index[(x + dx, y + dy)])
        for (x, y) in cells
        for dx, dy in ((1, 0), (0, 1))
        if (x + dx, y + dy) in index
    ]
    return SpatialGraph.from_edges(5.0 * np.array(cells, dtype=float), edges, cell_size=5.0)


def cells_of(graph: SpatialGraph, nodes: np.ndarray, origin: np.ndarray) -> set[tuple[int, int]]:
    """The cells ``(x, y)`` of ``nodes`` relative to the position ``origin`` (metres)."""
    relative = np.rint((graph.positions[nodes] - origin) / graph.cell_size).astype(int)
    return {(int(x), int(y)) for x, y in relative}


def edge_cells(graph: SpatialGraph, origin: np.ndarray) -> set[frozenset]:
    """Every undirected edge of ``graph`` as a pair of cells relative to ``origin``."""
    src, dst = graph.edge_index
    cell = lambda n: tuple(np.rint((graph.positions[n] - origin) / graph.cell_size).astype(int))  # noqa: E731
    return {frozenset((cell(u), cell(v))) for u, v in zip(src.tolist(), dst.tolist(), strict=True)}


def test_the_world_holds_exactly_what_the_robot_sees() -> None:
    """A 5 x 4 lattice with a hole at cell (2, 1); robot_0 sees 3 hops: the world is that
    ball, with its edges, its unvisited points, the teammate in it, and the team's clock."""
    graph = lattice(5, 4, holes=((2, 1),))
    env = marl_cover.parallel_env(graph=graph, num_robots=3, hops=3, max_steps=9)
    interest = [0, 3, 4, 9, 11, 14]
    observations, _ = env.reset(
        seed=0, options={"robot_nodes": [5, 6, 18], "interest_nodes": interest}
    )
    observations, *_ = env.step({"robot_0": NORTH, "robot_1": STAY, "robot_2": STAY})
    snapshot = env.snapshot()
    ego = snapshot.robot_node[0]
    assert ego == 9 and snapshot.visited[9]  # cell (0, 2), a point it has just visited
    origin = graph.positions[ego]
    ball = np.flatnonzero(graph.hop_distances(np.array([ego]), limit=3)[0] <= 3)
    in_ball = np.zeros(graph.num_nodes, dtype=bool)
    in_ball[ball] = True

    world = ego_world(observations["robot_0"], hops=3)
    seen = world.snapshot()
    w_origin = seen.graph.positions[seen.robot_node[0]]
    assert cells_of(seen.graph, np.arange(seen.graph.num_nodes), w_origin) == cells_of(
        graph, ball, origin
    )
    ball_cells = cells_of(graph, ball, origin)
    ball_edges = {e for e in edge_cells(graph, origin) if e <= ball_cells}
    assert edge_cells(seen.graph, w_origin) == ball_edges
    # robot_1 (cell (1, 1)) is 2 hops away, robot_2 (cell (4, 3)) 5: out of view
    assert cells_of(seen.graph, seen.robot_node, w_origin) == {(0, 0), (1, -1)}
    assert len(seen.robot_node) == 2
    unvisited = np.flatnonzero(snapshot.unvisited_interest & in_ball)  # 0, 11, 14; 3, 4 far
    assert cells_of(graph, unvisited, origin) == {(0, -2), (2, 0), (0, 1)}
    assert cells_of(seen.graph, np.flatnonzero(seen.unvisited_interest), w_origin) == {
        (0, -2),
        (2, 0),
        (0, 1),
    }
    assert seen.max_steps == 8 and seen.num_steps == 0  # the team's clock: 9 - 1 steps left
    # a teammate snapped onto the robot's own waypoint (continuous time) is left out
    crowded = dict(observations["robot_0"])
    teammate = np.flatnonzero(crowded["node_mask"] & (crowded["nodes"][:, 0] > 0))[1]
    crowded["node_pos"] = crowded["node_pos"].copy()
    crowded["node_pos"][teammate] = 0.0
    assert len(ego_world(crowded, hops=3).snapshot().robot_node) == 1
    crowded["node_pos"][teammate] = 0.5  # between waypoints: not an observation of this env
    with pytest.raises(ValueError, match=f"robot node {teammate} of the ego-graph stands on none"):
        ego_world(crowded, hops=3)
    assert ego_world(observations["robot_0"], hops=3, horizon=5).snapshot().max_steps == 5

    # the world shows robot 0 the same ego-graph: same nodes, positions and edges
    mine = world.observe_batch()
    real = observations["robot_0"]
    count = int(real["node_mask"].sum())
    assert int(mine["node_mask"][0].sum()) == count
    np.testing.assert_array_equal(mine["nodes"][0, :count], real["nodes"][:count])
    np.testing.assert_array_equal(mine["node_pos"][0, :count], real["node_pos"][:count])
    np.testing.assert_array_equal(mine["action_mask"][0], real["action_mask"])

    def edge_set(obs: dict) -> set:
        keep = np.asarray(obs["edge_mask"], dtype=bool)
        src, dst = obs["edge_index"][:, keep].tolist()
        return set(zip(src, dst, strict=True))

    assert edge_set({k: v[0] for k, v in mine.items()}) == edge_set(real)
    model = AggregationGNN(GNNConfig(kind="nonlinear", hops=3))
    single = {k: v[:1] for k, v in mine.items()}
    torch.testing.assert_close(
        GNNPolicy(model).logits({"a": {k: v[0] for k, v in single.items()}}),
        GNNPolicy(model).logits({"a": real}),
    )


def test_in_exploration_the_world_is_what_the_team_discovered() -> None:
    """A 6 x 1 corridor, sensor 5 m: from waypoint 0 the team knows 0 and 1, and the point of
    interest on 4 is undiscovered: the world holds two waypoints and no point."""
    graph = lattice(6, 1)
    env = marl_cover.parallel_env(
        graph=graph, num_robots=1, hops=5, task="exploration", sensor_range=5.0
    )
    observations, _ = env.reset(seed=0, options={"robot_nodes": [0], "interest_nodes": [4]})
    plain = ego_world(observations["robot_0"], hops=5).snapshot()
    assert plain.graph.num_nodes == 2 and not plain.unvisited_interest.any()


class FixedLogits(LocalRolloutPolicy):
    """The policy with the network's scores replaced by given ones (its rule under test)."""

    def __init__(self, logits: list[list[float]], **kwargs) -> None:  # noqa: ANN003
        super().__init__(AggregationGNN(GNNConfig(kind="linear", hops=4)), **kwargs)
        self.fixed = torch.tensor(logits, dtype=torch.float64)

    def logits(self, observations):  # noqa: ANN001, ANN201
        return self.fixed


def always(action: int):  # noqa: ANN201
    """A play-out policy: every robot takes ``action`` at every step (a stay where masked)."""
    return lambda states: np.full((len(states), len(states[0]["robot_nodes"])), action)


def test_near_ties_are_played_out_and_the_better_one_taken() -> None:
    """A 7-waypoint corridor, robot_0 on 3, points on 0, 1 and 5; four steps; the play-outs
    keep going the way of the first move. West (to 2) returns 2 (1, 0), east (to 4) returns 1
    (5), staying returns 0 under "stay"."""
    graph = lattice(7, 1)
    env = marl_cover.parallel_env(graph=graph, num_robots=1, hops=6, max_steps=4)
    observations, _ = env.reset(seed=0, options={"robot_nodes": [3], "interest_nodes": [0, 1, 5]})
    east_best = [[0.0, 1.0, -np.inf, 0.8, -np.inf]]  # east best, west 0.2 behind
    west, east = always(WEST), always(EAST)
    # under "west": west goes 2, 1, 0, 0 (2 points), east 4, 3, 2, 1 (1)
    policy = FixedLogits(east_best, margin=0.5, base=west)
    assert policy.act(observations) == {"robot_0": WEST}
    assert policy.counts == {"decisions": 1, "played": 1, "play_outs": 2, "changed": 1}
    policy = FixedLogits(east_best, margin=0.1, base=west)
    assert policy.act(observations) == {"robot_0": EAST}  # no near-tie: no play-out
    assert policy.counts == {"decisions": 1}
    # every unmasked move a candidate (never north or south): staying (3, 2, 1, 0) also
    # returns 2, and among the best returns the best logit (west's 0.8 over stay's 0) wins
    policy = FixedLogits(east_best, margin=1e9, base=west)
    assert policy.act(observations) == {"robot_0": WEST}
    assert policy.counts["play_outs"] == 3
    # under "east": west goes 2, 3, 4, 5 (1 point), east 4, 5, 6, 6 (1): a tie keeps the argmax
    policy = FixedLogits(east_best, margin=0.5, base=east)
    assert policy.act(observations) == {"robot_0": EAST}
    assert policy.counts["changed"] == 0


@pytest.mark.parametrize(("interest", "chosen"), [([0, 1, 5], WEST), ([0, 5, 6], EAST)])
@pytest.mark.parametrize("greedy_after", [0, 1, 2])
def test_greedy_finishes_the_play_outs(interest: list[int], chosen: int, greedy_after: int) -> None:
    """The corridor of the test above, greedy (K = 4, the model's) after ``greedy_after``
    moves of "stay". Points 0, 1, 5: west (2) then toward 1, 0 returns 2 even after a stay, east
    (4) then 5 returns 1. Points 0, 5, 6: east then 5, 6 returns 2, west then 1, 0 returns 1:
    the argmax east stays."""
    env = marl_cover.parallel_env(graph=lattice(7, 1), num_robots=1, hops=6, max_steps=4)
    observations, _ = env.reset(seed=0, options={"robot_nodes": [3], "interest_nodes": interest})
    policy = FixedLogits(
        [[0.0, 1.0, -np.inf, 0.8, -np.inf]],
        margin=0.5,
        base=always(STAY),
        greedy_after=greedy_after,
    )
    assert policy.act(observations) == {"robot_0": chosen}
    assert policy.counts["play_outs"] == 2
    assert policy.counts["changed"] == int(chosen == WEST)
    never = FixedLogits([[0.0, 1.0, -np.inf, 0.8, -np.inf]], margin=0.5, base=always(STAY))
    assert never.act(observations) == {"robot_0": EAST}  # on "stay" both return 0: a tie
    with pytest.raises(ValueError, match=r"greedy_after must be >= 0 moves, got -1"):
        FixedLogits([[0.0] * 5], greedy_after=-1)


def test_margin_zero_is_the_gnn_and_bad_settings_are_named() -> None:
    graph = lattice(4, 3)
    torch.manual_seed(0)
    model = AggregationGNN(GNNConfig(kind="nonlinear", hops=3))
    env = marl_cover.parallel_env(graph=graph, num_robots=2, hops=3, max_steps=5)
    observations, _ = env.reset(seed=1)
    for _ in range(4):
        plain = GNNPolicy(model).act(observations)
        policy = LocalRolloutPolicy(model, margin=0.0)
        assert policy.act(observations) == plain
        assert policy.counts["played"] == 0
        observations, *_ = env.step(plain)
    with pytest.raises(ValueError, match="margin must be >= 0"):
        LocalRolloutPolicy(model, margin=-0.5)
    with pytest.raises(ValueError, match="horizon must be >= 1"):
        LocalRolloutPolicy(model, horizon=0)
    observations, _ = env.reset(seed=1)
    broken = {a: dict(o) for a, o in observations.items()}
    del broken["robot_1"]["steps_left"]
    policy = FixedLogits([[0.0, 1.0, 1.0, 1.0, 1.0]] * 2, margin=0.5)
    policy.fixed = torch.where(
        torch.tensor(np.stack([o["action_mask"] for o in observations.values()])) > 0,
        torch.ones(2, 5, dtype=torch.float64),
        torch.tensor(-np.inf, dtype=torch.float64),
    )
    with pytest.raises(KeyError, match="robot_1 has no 'steps_left'"):
        policy.act(broken)


def test_cli_plays_the_decentralized_rollout(tmp_path) -> None:
    """``evaluate.py policy=gnn_local_rollout``: margin 0 plays the GNN's episodes; a wide
    margin plays moves out, and the counts say how many, in coverage and in exploration."""
    from helpers import run_cli

    from marl_cover.agents.models.checkpoints import save_model

    torch.manual_seed(2)
    model_file = tmp_path / "m.pt"
    save_model(model_file, AggregationGNN(GNNConfig(kind="nonlinear", hops=3)), {"note": "random"})
    common = [f"model={model_file}", "episodes=2", "env.num_robots=3", "env.max_steps=8"]
    common += ["env.city_size=80"]
    records = {}
    for name, extra in (
        ("gnn", ["policy=gnn"]),
        ("zero", ["policy=gnn_local_rollout", "gnn.margin=0"]),
        ("wide", ["policy=gnn_local_rollout", "gnn.margin=100", "gnn.horizon=4"]),
        ("finish", ["policy=gnn_local_rollout", "gnn.margin=100", "gnn.greedy_after=1"]),
        ("explore", ["policy=gnn_local_rollout", "env.task=exploration", "gnn.margin=100"]),
    ):
        out = tmp_path / f"{name}.json"
        result = run_cli("evaluate", *common, *extra, f"out={out}")
        assert result.returncode == 0, result.stderr
        records[name] = json.loads(out.read_text())["summary"]
    rewards = {k: [r["reward"] for r in v["results"]] for k, v in records.items()}
    assert rewards["zero"] == rewards["gnn"]
    assert records["zero"]["policy_counts"]["decisions"] == 2 * 8 * 3
    assert "played" not in records["zero"]["policy_counts"]
    for name in ("wide", "finish", "explore"):
        counts = records[name]["policy_counts"]
        assert counts["decisions"] == 2 * 8 * 3 and 0 < counts["played"] <= counts["decisions"]
        assert 2 * counts["played"] <= counts["play_outs"] <= 5 * counts["played"]
