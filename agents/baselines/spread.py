"""Near-ties of a policy's action scores broken toward the move that leads away from teammates.

A decoding rule for the GNN (``GNNPolicy(spread_margin=...)``), read from each robot's own
ego-graph: the moves whose logit lies within ``margin`` of the best are candidates; each
candidate's target waypoint is scored by its hop distance, on the waypoints of the ego-graph,
to the nearest teammate in view (a teammate stands on the waypoint at its position); the robot
takes the best-scoring move unless another candidate leads strictly farther from its nearest
teammate, and then the highest-scoring of the farthest candidates. A robot with no teammate in
view, or a single candidate, keeps its argmax; a masked action is never a candidate.

The GNN's losses concentrate in a few decisions where robots crowd one region; this rule spreads
the team only where the network itself rates the moves about equal (its figures: the results
page of the documentation).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from marl_cover.ego import NODE_FEATURES, NUM_ACTIONS

_IS_ROBOT = NODE_FEATURES.index("is_robot")
_IS_WAYPOINT = NODE_FEATURES.index("is_waypoint")


def teammate_waypoints(observation: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The teammates in one ego-graph and the waypoints they stand on.

    Args:
        observation: One robot's padded ego-graph (``nodes``, ``node_pos``, ``node_mask``);
            node 0 is the ego robot.

    Returns:
        The teammates' robot nodes ``(T,)`` and ``(T, M)`` bool: ``True`` at the waypoint node
        in the same position as teammate ``t`` (a teammate stands on its waypoint).
    """
    nodes, mask = observation["nodes"], np.asarray(observation["node_mask"], dtype=bool)
    robot = mask & (nodes[:, _IS_ROBOT] > 0)
    robot[0] = False  # the ego robot is no teammate
    waypoint = mask & (nodes[:, _IS_WAYPOINT] > 0)
    positions = observation["node_pos"]
    on = (positions[None, :, :] == positions[robot][:, None, :]).all(axis=-1) & waypoint
    return np.flatnonzero(robot), on


def teammate_distances(observation: Mapping[str, np.ndarray]) -> np.ndarray:
    """Hop distance ``(M,)`` from each node of one ego-graph to the nearest teammate in view,
    along waypoint-waypoint edges of the ego-graph (``inf`` where none is reachable, and
    everywhere when no teammate is in view).

    Args:
        observation: One robot's padded ego-graph (``nodes``, ``node_pos``, ``node_mask``,
            ``edge_index``, ``edge_mask``); node 0 is the ego robot.
    """
    nodes, mask = observation["nodes"], np.asarray(observation["node_mask"], dtype=bool)
    num_nodes = len(nodes)
    teammates, on = teammate_waypoints(observation)  # (T,), (T, M)
    if not len(teammates):
        return np.full(num_nodes, np.inf)
    waypoint = mask & (nodes[:, _IS_WAYPOINT] > 0)
    sources = np.flatnonzero(on.any(axis=0))
    src, dst = observation["edge_index"]
    live = np.asarray(observation["edge_mask"], dtype=bool) & waypoint[src] & waypoint[dst]
    graph = csr_matrix(
        (np.ones(int(live.sum())), (src[live], dst[live])), shape=(num_nodes, num_nodes)
    )
    return dijkstra(graph, directed=True, indices=sources, unweighted=True, min_only=True)


def spread_actions(
    logits: np.ndarray, observations: Sequence[Mapping[str, np.ndarray]], margin: float
) -> np.ndarray:
    """Each robot's move ``(R,)``: its argmax, or a near-tied move that leads farther from its
    nearest teammate in view (see the module docstring).

    Args:
        logits: Action scores ``(R, 5)``, ``-inf`` for masked actions.
        observations: Each robot's own ego-graph, in the order of ``logits`` (read only for
            the robots with a near-tie).
        margin: Moves within this much of the best logit are candidates (``0``: exact ties
            only).

    Raises:
        ValueError: ``margin`` is negative.
    """
    if not margin >= 0:
        raise ValueError(f"the spread margin must be >= 0, got {margin}")
    logits = np.asarray(logits, dtype=np.float64)
    actions = logits.argmax(axis=-1)  # (R,)
    for i, best in enumerate(actions):
        candidates = np.flatnonzero(
            np.isfinite(logits[i]) & (logits[i] >= logits[i, best] - margin)
        )
        if len(candidates) < 2:
            continue
        try:
            distance = teammate_distances(observations[i])  # (M,)
        except KeyError as error:
            raise KeyError(f"the observation of robot {i} has no {error.args[0]!r}") from None
        targets = observations[i]["edge_index"][0, :NUM_ACTIONS]  # action edge k: target -> ego
        spread = distance[targets[candidates]]  # (C,)
        if not np.isfinite(spread).any() or spread[candidates == best][0] == spread.max():
            continue
        farthest = candidates[spread == spread.max()]
        actions[i] = farthest[np.argmax(logits[i, farthest])]
    return actions
