"""The spread tie-break (``marl_cover.agents.baselines.spread``): exact choices on a hand-built
U-shaped graph."""

from __future__ import annotations

import numpy as np
import pytest

import marl_cover
from marl_cover.agents.baselines.spread import spread_actions, teammate_distances
from marl_cover.graph import SpatialGraph

STAY, EAST, NORTH, WEST, SOUTH = range(5)
INF = -np.inf


@pytest.fixture
def u_graph() -> SpatialGraph:
    """Seven waypoints, cell size 5 m; 1 and 5 are 10 m apart but 4 hops::

    6 - 5 - 4
            |
            3
            |
    0 - 1 - 2
    """
    positions = np.array([(0, 0), (5, 0), (10, 0), (10, 5), (10, 10), (5, 10), (0, 10)], float)
    return SpatialGraph.from_edges(positions, [(i, i + 1) for i in range(6)], cell_size=5.0)


def views(graph: SpatialGraph, hops: int) -> list[dict[str, np.ndarray]]:
    """Both robots' ego-graphs, robot 0 on waypoint 1 and robot 1 on waypoint 5."""
    env = marl_cover.parallel_env(graph=graph, num_robots=2, hops=hops)
    observations, _ = env.reset(
        seed=0, options={"robot_nodes": [1, 5], "interest_nodes": [0, 2, 4, 6]}
    )
    return list(observations.values())


def test_distances_run_along_the_ego_graph_to_the_nearest_teammate(u_graph) -> None:  # noqa: ANN001
    batch = views(u_graph, hops=4)
    robot_0 = batch[0]
    distance = teammate_distances(robot_0)
    # node 0: the ego robot; 1..6: waypoints 0..5 (6 is five hops away); 7: robot_1 on 5
    assert distance[1:7].tolist() == [5, 4, 3, 2, 1, 0]
    assert np.isinf(distance[[0, 7]]).all() and np.isinf(distance[8:]).all()
    robot_1 = batch[1]
    # robot_1 sees waypoints 1..6 (0 is five hops away): robot_0 stands on 1
    assert teammate_distances(robot_1)[1:7].tolist() == [0, 1, 2, 3, 4, 5]
    alone = views(u_graph, hops=3)[0]
    assert np.isinf(teammate_distances(alone)).all()  # robot_1 is four hops away


def test_near_ties_go_away_from_the_teammate_by_hops_not_metres(u_graph) -> None:  # noqa: ANN001
    """West (to 0) and east (to 2) are equally far from robot_1 in metres; by hops west is 5
    away and east 3, so a near-tie goes west. Robot_1's near-tie goes west too (to 6)."""
    batch = views(u_graph, hops=4)
    logits = np.array(
        [
            [0.0, 1.0, INF, 0.9, INF],  # robot_0: east best, west 0.1 behind
            [0.0, 1.0, INF, 0.7, INF],  # robot_1: east (to 4) best, west (to 6) 0.3 behind
        ]
    )
    assert spread_actions(logits, batch, margin=0.5).tolist() == [WEST, WEST]
    assert spread_actions(logits, batch, margin=0.2).tolist() == [WEST, EAST]
    assert spread_actions(logits, batch, margin=0.0).tolist() == [EAST, EAST]
    # a huge margin makes every unmasked move a candidate, never a masked one; staying
    # (distance 4 from robot_1) loses to west (5); among the farthest, the best logit
    assert spread_actions(logits, batch, margin=1e9).tolist() == [WEST, WEST]
    alone = views(u_graph, hops=3)
    assert spread_actions(logits, alone, margin=0.5).tolist() == [EAST, EAST]  # none in view
    with pytest.raises(ValueError, match="margin must be >= 0"):
        spread_actions(logits, batch, margin=-0.1)


def test_the_gnn_policy_breaks_its_own_ties(u_graph) -> None:  # noqa: ANN001
    torch = pytest.importorskip("torch")
    from marl_cover.agents.models import AggregationGNN, GNNConfig
    from marl_cover.agents.models.policy import GNNPolicy

    torch.manual_seed(0)
    model = AggregationGNN(GNNConfig(kind="nonlinear", hops=4))
    env = marl_cover.parallel_env(graph=u_graph, num_robots=2, hops=4)
    observations, _ = env.reset(seed=0, options={"robot_nodes": [1, 5]})
    policy = GNNPolicy(model, spread_margin=1e9)
    logits = policy.logits(observations).numpy()
    expected = spread_actions(logits, list(observations.values()), margin=1e9)
    assert list(policy.act(observations).values()) == expected.tolist() == [WEST, WEST]
    plain = GNNPolicy(model).act(observations)
    assert list(plain.values()) == logits.argmax(-1).tolist()
    for kwargs in ({"centralized": True}, {"deterministic": False}):
        with pytest.raises(ValueError, match="centralized=False and deterministic=True"):
            GNNPolicy(model, spread_margin=0.5, **kwargs)
    with pytest.raises(ValueError, match="spread_margin must be >= 0"):
        GNNPolicy(model, spread_margin=-1.0)
