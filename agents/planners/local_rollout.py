"""Decentralized one-step rollout: each robot plays its near-tied moves out on its own ego-graph.

The omniscient rollout policy (:mod:`marl_cover.agents.planners.rollout`) plays moves out on the
whole state. Here a robot plans with nothing but its observation:

1. Its GNN scores its moves (the shipped network on its own ego-graph, as :class:`GNNPolicy`).
   The moves whose logit lies within ``margin`` of the best are its candidates; a robot with a
   single candidate takes it (most decisions: no play-out at all).
2. Otherwise it builds a world from its ego-graph (:func:`ego_world`): a coverage environment
   on the waypoints and edges it sees, with the unvisited points of interest it sees, itself
   and the teammates in view on their waypoints, and as many steps as the team's clock has
   left (or ``horizon``). In exploration that world is what the team has discovered within
   the robot's view.
3. It plays each candidate out in that world, exactly
   (:func:`~marl_cover.agents.planners.rollout.play_out`): its
   first move the candidate, its teammates' the GNN's argmax in that world, every robot on
   the GNN's argmax afterwards. It keeps its argmax unless another candidate returns strictly
   more, and then takes the best logit among those that return most. With ``greedy_after``
   the network plays only a play-out's first moves and greedy the rest, in a compiled kernel
   (:func:`~marl_cover.agents.baselines.greedy.greedy_return`): the network's passes are most
   of the cost, and in the quadrotor mission two of its moves keep about 60% of the gain at
   five times the speed.

Teammates plan the same way on their own views, at the same time, without communicating: the
policy is as decentralized as the GNN. The robot's world model is wrong where its view ends
(teammates beyond it, the map beyond it, in exploration the undiscovered map), and in its
world it has the collision resolver's first priority (its figures: the results page of the
documentation).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
from typing import Any

import numpy as np

from marl_cover.agents.baselines.greedy import greedy_return
from marl_cover.agents.baselines.spread import teammate_waypoints
from marl_cover.agents.models.policy import GNNPolicy
from marl_cover.agents.planners.rollout import BasePolicy, GNNArgmax, play_out_greedy_finish
from marl_cover.config import CoverageConfig
from marl_cover.ego import NODE_FEATURES, NUM_EGO_ACTION_EDGES
from marl_cover.env import CoverageEnv
from marl_cover.graph import SpatialGraph

_IS_WAYPOINT, _IS_INTEREST = (NODE_FEATURES.index(name) for name in ("is_waypoint", "is_interest"))


def ego_world(
    observation: Mapping[str, np.ndarray],
    hops: int,
    horizon: int | None = None,
) -> CoverageEnv:
    """A coverage environment, reset, on what one robot's ego-graph holds.

    Robot 0 of the world is the observing robot; robots ``1..`` are its teammates in view, in
    the order of the ego-graph (one robot per waypoint: a teammate snapped to a waypoint that
    an earlier robot holds, as happens in continuous time, is left out). Action slots keep
    their directions, so a move in the world is the same move in the real environment.

    Args:
        observation: One robot's padded ego-graph with ``steps_left`` (the environment's
            observation of one agent).
        hops: Ego-graph radius of the world's robots (the GNN's receptive field).
        horizon: Most steps the world runs (``None``: as many as the team's clock has left).

    Raises:
        KeyError: A key of the observation is missing (named).
        ValueError: A teammate in the ego-graph stands on none of its waypoints.
    """
    nodes = observation["nodes"]
    node_pos = np.asarray(observation["node_pos"], dtype=np.float64)
    mask = np.asarray(observation["node_mask"], dtype=bool)
    waypoint = mask & (nodes[:, _IS_WAYPOINT] > 0)
    ids = np.flatnonzero(waypoint)  # (W,) ego-graph nodes that are waypoints
    local = np.full(len(nodes), -1, dtype=np.int64)
    local[ids] = np.arange(len(ids))
    src, dst = observation["edge_index"]
    live = np.asarray(observation["edge_mask"], dtype=bool).copy()
    live[:NUM_EGO_ACTION_EDGES] = False  # the ego robot's own action edges
    live &= waypoint[src] & waypoint[dst]
    cell_size = _cell_size(node_pos, src[live], dst[live], observation["edge_attr"][live, 0])
    once = live & (src < dst)
    edges = np.column_stack([local[src[once]], local[dst[once]]])  # (E, 2)
    graph = SpatialGraph.from_edges(node_pos[ids] * cell_size, edges, cell_size)
    own = local[observation["edge_index"][0, 0]]  # the stay edge: own waypoint -> ego robot
    teammates, on = teammate_waypoints(observation)  # (T,), (T, M)
    at = on[:, ids]  # (T, W)
    if not at.any(axis=1).all():
        node = int(teammates[np.flatnonzero(~at.any(axis=1))[0]])
        raise ValueError(f"robot node {node} of the ego-graph stands on none of its waypoints")
    robot_nodes = np.concatenate([[own], at.argmax(axis=1)])  # (1 + T,)
    # In continuous time two robots can snap to one waypoint: the world keeps the first
    # (the observing robot before its teammates), as the discrete environment holds one.
    _, first = np.unique(robot_nodes, return_index=True)
    robot_nodes = robot_nodes[np.sort(first)]
    interest = nodes[ids, _IS_INTEREST] > 0
    steps = int(observation["steps_left"])
    return _world(graph, robot_nodes, interest, hops, steps, horizon)


def _world(
    graph: SpatialGraph,
    robot_nodes: np.ndarray,
    interest: np.ndarray,
    hops: int,
    steps: int,
    horizon: int | None,
) -> CoverageEnv:
    """A coverage environment on ``graph``, reset with robots on ``robot_nodes`` ``(R,)`` (robot
    0 the planning one) and the points of interest ``interest`` ``(N,)`` bool not under a robot,
    for ``steps`` (at most ``horizon``; at least 1)."""
    interest = interest.copy()
    interest[robot_nodes] = False
    if horizon is not None:
        steps = min(steps, horizon)
    config = CoverageConfig(
        graph=graph, num_robots=len(robot_nodes), hops=hops, max_steps=max(steps, 1)
    )
    world = CoverageEnv(config)
    world.reset(
        seed=0,
        options={"robot_nodes": robot_nodes, "interest_nodes": np.flatnonzero(interest)},
    )
    return world


def _cell_size(node_pos: np.ndarray, src: np.ndarray, dst: np.ndarray, metres: np.ndarray) -> float:
    """Lattice spacing in metres, from an edge's length in cells and in metres (1.0 with no
    waypoint edge in view: a lone waypoint has no distances to scale)."""
    if len(src) == 0:
        return 1.0
    cells = float(np.linalg.norm(node_pos[src[0]] - node_pos[dst[0]]))
    return float(metres[0]) / cells


class LocalRolloutPolicy(GNNPolicy):
    """The GNN with each robot's near-tied moves played out on its own ego-graph (see the
    module docstring).

    Args:
        model: An :class:`~marl_cover.agents.models.gnn.AggregationGNN`.
        margin: Moves within this much of the best logit are played out (``0``: exact ties).
        horizon: Most steps of each play-out (``None``: to the end of the episode).
        base: The play-outs' policy over the world's states (default: the GNN's argmax,
            :class:`~marl_cover.agents.planners.rollout.GNNArgmax`).
        greedy_after: After this many joint moves of a play-out by ``base`` (the first of
            them: the candidate and the teammates' moves), greedy plays the rest (with the
            GNN's horizon K, staying when nothing is within reach:
            :func:`~marl_cover.agents.baselines.greedy.greedy_return`, a compiled play-out, hundreds
            of times cheaper than the network's steps); ``0``: greedy from the first move on, the
            teammates' first moves included; ``None``: ``base`` to the end.

    Attributes:
        counts: ``decisions`` (robot decisions), ``played`` (those with a near-tie, played
            out), ``changed`` (those that left the argmax) and ``play_outs``.
        accept: After :meth:`act`: ``(R,)`` bit masks of the moves that returned as much as the
            chosen one (bit ``a`` for action ``a``; the chosen move alone where nothing was
            played out), as the routing experts and
            :class:`~marl_cover.agents.planners.rollout.RolloutPolicy` record them for imitation.

    Raises:
        ValueError: ``margin`` or ``greedy_after`` is negative, or ``horizon`` is below 1.
    """

    def __init__(
        self,
        model: Any,
        margin: float = 1.0,
        horizon: int | None = None,
        base: BasePolicy | None = None,
        greedy_after: int | None = None,
    ) -> None:
        if not margin >= 0:
            raise ValueError(f"the rollout margin must be >= 0, got {margin}")
        if horizon is not None and horizon < 1:
            raise ValueError(f"the rollout horizon must be >= 1 step, got {horizon}")
        if greedy_after is not None and greedy_after < 0:
            raise ValueError(f"the rollout's greedy_after must be >= 0 moves, got {greedy_after}")
        super().__init__(model)
        self.margin = float(margin)
        self.horizon = horizon
        self.base = base if base is not None else GNNArgmax(model)
        self.greedy_after = greedy_after
        self.counts: Counter[str] = Counter()
        self.accept = np.zeros(0, dtype=np.int64)

    def reset(self, seed: int | None = None) -> None:  # noqa: ARG002 (the harness's hook)
        """Starts an episode: zeroes the counts (the evaluation harness's hook)."""
        self.counts = Counter()

    def act(self, observations: dict[str, dict[str, np.ndarray]]) -> dict[str, int]:
        """Each robot's action from its own ego-graph (decentralized)."""
        logits = self.logits(observations).numpy().astype(np.float64)  # (R, 5)
        actions = logits.argmax(axis=-1)  # (R,)
        self.accept = np.zeros(len(actions), dtype=np.int64)
        for i, agent in enumerate(observations):
            actions[i], self.accept[i] = self._decide(logits[i], observations[agent], agent)
        self.counts["decisions"] += len(actions)
        return dict(zip(observations, actions.tolist(), strict=True))

    def _decide(
        self, logits: np.ndarray, observation: Mapping[str, np.ndarray], agent: str
    ) -> tuple[int, int]:
        """One robot's move from its logits ``(5,)`` and its observation, and the bit mask of
        the moves that returned as much."""
        best = int(logits.argmax())
        candidates = np.flatnonzero(np.isfinite(logits) & (logits >= logits[best] - self.margin))
        if len(candidates) < 2:
            return best, 1 << best
        returns = self._play_outs(self._world(observation, agent), candidates)  # (C,)
        self.counts["played"] += 1
        self.counts["play_outs"] += len(candidates)
        top = candidates[returns == returns.max()]
        accept = sum(1 << int(a) for a in top)
        if returns.max() <= returns[candidates == best][0]:
            return best, accept
        self.counts["changed"] += 1
        return int(top[np.argmax(logits[top])]), accept

    def _world(self, observation: Mapping[str, np.ndarray], agent: str) -> CoverageEnv:
        """The world ``agent`` plays its candidates out in: its ego-graph's."""
        try:
            return ego_world(observation, self.model.config.hops, self.horizon)
        except KeyError as error:
            raise KeyError(f"the observation of {agent} has no {error.args[0]!r}") from None

    def _play_outs(self, world: CoverageEnv, candidates: np.ndarray) -> np.ndarray:
        """The return ``(C,)`` of each candidate first move of robot 0 in ``world``."""
        hops = self.model.config.hops
        if self.greedy_after == 0:
            first = np.full((len(candidates), world.config.num_robots), -1, dtype=np.int64)
            first[:, 0] = candidates
            return np.array([greedy_return(world, hops, f) for f in first])
        joint = np.asarray(self.base([world.state()])[0])  # (1 + T,) the base in that world
        joints = np.repeat(joint[None, :], len(candidates), axis=0)  # (C, 1 + T)
        joints[:, 0] = candidates
        return play_out_greedy_finish(world, self.base, joints, self.greedy_after, hops)
