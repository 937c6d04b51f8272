"""Labels that tie: every first hop of a shortest path is as good as the expert's own."""

from __future__ import annotations

import math

import numpy as np
import pytest

from marl_cover.agents.experts.expert import lowest_action, shortest_moves, step_toward
from marl_cover.agents.training.datasets import Episode, read_shard, trajectory_ties, write_shard
from marl_cover.graph import SpatialGraph

torch = pytest.importorskip("torch")

# actions: 0 stay, 1 east, 2 north, 3 west, 4 south
STAY, EAST, NORTH = 1 << 0, 1 << 1, 1 << 2


def grid(missing: tuple[int, ...] = ()) -> SpatialGraph:
    """A 3 x 3 lattice, cell size 1, node ``3 y + x`` at ``(x, y)``, minus ``missing``::

    6 - 7 - 8
    |   |   |
    3 - 4 - 5
    |   |   |
    0 - 1 - 2
    """
    keep = [n for n in range(9) if n not in missing]
    index = {n: k for k, n in enumerate(keep)}
    positions = np.array([(n % 3, n // 3) for n in keep], dtype=float)
    edges = [
        (index[a], index[b])
        for a in keep
        for b in (a + 1, a + 3)
        if b in index and (b == a + 3 or a % 3 < 2)
    ]
    return SpatialGraph.from_edges(positions, edges, cell_size=1.0)


def test_shortest_moves_are_every_first_hop_of_a_shortest_path() -> None:
    g = grid()
    robots = np.array([0, 0, 0, 0, 4])
    goals = np.array([8, 2, -1, 0, 4])
    mask = shortest_moves(g, robots, goals)
    assert mask.tolist() == [EAST | NORTH, EAST, STAY, STAY, STAY]
    # the expert's tie-break is the lowest slot, as it always was
    assert lowest_action(mask).tolist() == [1, 1, 0, 0, 0]
    assert np.array_equal(step_toward(g, robots, goals), lowest_action(mask))
    # without waypoint 1, the only way from 0 to 2 starts north
    g = grid(missing=(1,))
    # (waypoint 2 is index 1 once waypoint 1 is gone)
    assert shortest_moves(g, np.array([0]), np.array([1])).tolist() == [NORTH]
    assert shortest_moves(g, np.array([0]), np.array([-1])).tolist() == [STAY]


def episode(path: list[int], interest: list[int]) -> Episode:
    """One robot walking ``path`` on the full 3 x 3 grid."""
    g = grid()
    steps = list(zip(path[:-1], path[1:], strict=True))
    moves = {1: 1, 3: 2, -1: 3, -3: 4, 0: 0}
    return Episode(
        seed=0,
        graph=g,
        interest=np.isin(np.arange(9), interest),
        robot_node=np.array(path, dtype=np.int64)[:, None],
        actions=np.array([[moves[b - a]] for a, b in steps], dtype=np.int8),
    )


@pytest.mark.parametrize(
    ("path", "interest", "expected"),
    [
        # straight to 8 along a shortest path: east or north until the last column
        ([0, 1, 2, 5, 8], [8], [EAST | NORTH, EAST | NORTH, NORTH, NORTH]),
        # a wait first: that step took longer than the distance, so only the label is kept
        ([0, 0, 1, 2, 5, 8], [8], [STAY, EAST | NORTH, EAST | NORTH, NORTH, NORTH]),
        # 4 is scored on the way: the hops toward it, then toward 8
        ([0, 1, 4, 5, 8], [4, 8], [EAST | NORTH, NORTH, EAST | NORTH, NORTH]),
        # nothing left to score after 8: the last moves keep their label only
        ([0, 3, 4, 1], [3], [NORTH, EAST, 1 << 4]),
    ],
)
def test_trajectory_ties_accept_the_moves_that_score_as_early(path, interest, expected) -> None:
    assert trajectory_ties(episode(path, interest))[:, 0].tolist() == expected


def test_tie_sets_round_trip_through_shards(tmp_path) -> None:
    plain = episode([0, 1, 2, 5, 8], [8])
    tied = Episode(**{**plain.__dict__, "seed": 1, "accept": trajectory_ties(plain)})
    write_shard(tmp_path / "tied.npz", [tied])
    write_shard(tmp_path / "plain.npz", [plain])
    (back,) = read_shard(tmp_path / "tied.npz")
    assert np.array_equal(back.accept, tied.accept)
    assert read_shard(tmp_path / "plain.npz")[0].accept is None


def test_the_tie_loss_is_the_log_probability_of_the_accepted_set() -> None:
    from marl_cover.agents.models import AggregationGNN, GNNConfig
    from marl_cover.agents.models.logits import action_logits
    from marl_cover.agents.training.bc import batch_loss
    from marl_cover.agents.training.data import GraphTable, collate_states, episode_transitions

    torch.manual_seed(0)
    model = AggregationGNN(GNNConfig(hops=3, hidden=8)).requires_grad_(False)
    ep = episode([0, 1, 2, 5, 8], [8])
    ep = Episode(**{**ep.__dict__, "accept": trajectory_ties(ep)})
    table = GraphTable([ep.graph])
    batch = episode_transitions([ep], table.max_nodes)
    assert batch["accept"][:, 0].tolist() == [6, 6, 4, 4]
    nodes, edge_index, edge_attr, action_edges = collate_states(batch, table)
    logits = action_logits(model, (nodes, edge_index, edge_attr), action_edges)
    log_p = torch.log_softmax(logits, -1)
    sets = [[1, 2], [1, 2], [2], [2]]
    expected = -sum(torch.logsumexp(log_p[t, s], 0) for t, s in enumerate(sets)) / 4
    label = -log_p[torch.arange(4), batch["action"][:, 0]].mean()
    tied, metrics = batch_loss(model, batch, table, ties=True)
    plain, _ = batch_loss(model, batch, table)
    assert math.isclose(float(tied), float(expected), rel_tol=1e-5)
    assert math.isclose(float(plain), float(label), rel_tol=1e-5)
    assert math.isclose(metrics["cross_entropy"], float(label), rel_tol=1e-5)
    assert float(tied) < float(plain)  # the sets hold the labels and more
