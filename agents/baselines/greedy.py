"""Greedy baseline: one hop toward the nearest unvisited point of interest within K hops.

Rule (both variants give the same actions):

- A robot looks at the waypoints within ``hops`` hops of its own waypoint and at its *targets*
  among them: the unvisited points of interest and, in exploration, the frontier waypoints
  (discovered waypoints next to undiscovered ones; in coverage there are none). Distances are
  hops on the graph the robot observes, which in exploration is the known graph only.
- It takes the move whose target waypoint is nearest (in hops) to any target; ties go to
  the lowest action slot (east, north, west, south). This is one hop along a shortest path to a
  nearest target: a known point of interest or the nearest edge of the unknown.
- When no point of interest lies within ``hops`` hops it stays (action 0), or, with
  ``fallback="random"``, takes a uniformly random available move from the policy's own seeded
  generator (the paper's code moved at random).

:class:`GreedyPolicy` uses only each robot's own ego-observation; :class:`CentralizedGreedyPolicy`
computes every robot's action from ``state()`` with one multi-source breadth-first search.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from marl_cover.ego import NODE_FEATURES

try:  # the compiled play-out of greedy_return (optional dependency numba)
    from marl_cover.agents.baselines._greedy_numba import greedy_play_out as _compiled_play_out
except ImportError:  # pragma: no cover - numba is installed in CI
    _compiled_play_out = None  # type: ignore[assignment]

FALLBACKS = ("stay", "random")
#: Node-feature columns of a target: an unvisited point of interest or a frontier waypoint.
TARGET_COLUMNS = [NODE_FEATURES.index("is_interest"), NODE_FEATURES.index("is_frontier")]


def _distance_to_interest(
    nodes: np.ndarray, edge_index: np.ndarray, edge_mask: np.ndarray, limit: int
) -> np.ndarray:
    """Hop distance from every node to the nearest target (point of interest or frontier
    node), ``inf`` beyond ``limit``.

    Args:
        nodes: ``(num_nodes, 4)`` node features.
        edge_index: ``(2, num_edges)`` edges.
        edge_mask: ``(num_edges,)`` real edges.
        limit: Largest distance computed.
    """
    num_nodes = nodes.shape[0]
    senders, receivers = edge_index[:, edge_mask]
    # The graph is symmetric, so distances *to* the sources equal distances *from* them.
    adjacency = csr_matrix(
        (np.ones(len(senders)), (senders, receivers)), shape=(num_nodes, num_nodes)
    )
    sources = np.flatnonzero((nodes[:, TARGET_COLUMNS] > 0).any(axis=1))
    if len(sources) == 0:
        return np.full(num_nodes, np.inf)
    return dijkstra(adjacency, indices=sources, unweighted=True, limit=limit, min_only=True)


class _GreedyBase:
    def __init__(self, hops: int = 19, fallback: str = "stay", seed: int | None = None) -> None:
        if hops < 1:
            raise ValueError(f"hops must be >= 1, got {hops}")
        if fallback not in FALLBACKS:
            raise ValueError(f"fallback must be one of {FALLBACKS}, got {fallback!r}")
        self.hops = hops
        self.fallback = fallback
        self.seed = seed
        self._rng = np.random.default_rng(seed)

    @property
    def deterministic(self) -> bool:
        """Whether the same observations always give the same actions."""
        return self.fallback == "stay"

    def reset(self, seed: int | None = None) -> None:
        """Re-seeds the generator used by ``fallback="random"``."""
        self._rng = np.random.default_rng(self.seed if seed is None else seed)

    def _choose(self, move_distance: np.ndarray, action_mask: np.ndarray) -> np.ndarray:
        """Actions from the distance-to-interest of each move target.

        Args:
            move_distance: ``(R, 4)`` distance from each move slot's target to the nearest point
                of interest (``inf`` if none or masked).
            action_mask: ``(R, 5)`` available actions.

        Returns:
            ``(R,)`` int64 actions.
        """
        move_distance = np.where(action_mask[:, 1:] > 0, move_distance, np.inf)
        best = np.argmin(move_distance, axis=1)  # first minimum: lowest slot
        reach = move_distance[np.arange(len(best)), best] + 1 <= self.hops
        actions = np.where(reach, best + 1, 0)
        if self.fallback == "random":
            for i in np.flatnonzero(~reach):
                moves = np.flatnonzero(action_mask[i, 1:]) + 1
                actions[i] = self._rng.choice(moves) if len(moves) else 0
        return actions.astype(np.int64)


class GreedyPolicy(_GreedyBase):
    """Decentralized greedy: each robot decides from its own ego-observation.

    Args:
        hops: Horizon K (default 19, the paper's); only points of interest within K hops count (at
            most the env's ``hops``, which bounds what an ego-graph shows).
        fallback: ``"stay"`` or ``"random"`` when nothing is within reach.
        seed: Seed of the generator of ``fallback="random"``.
    """

    def act(self, observations: dict[str, dict[str, np.ndarray]]) -> dict[str, int]:
        """Actions of every robot in ``observations`` (agent name -> ego-observation)."""
        agents = list(observations)
        if not agents:
            return {}
        batch = {
            key: np.stack([observations[a][key] for a in agents])
            for key in ("nodes", "edge_index", "edge_mask", "action_mask")
        }
        return dict(zip(agents, self.act_batch(batch).tolist(), strict=True))

    def act_batch(self, batch: dict[str, np.ndarray]) -> np.ndarray:
        """Actions from ego-observations stacked on a leading robot axis, ``(R,)`` int64."""
        nodes, edge_index, edge_mask = batch["nodes"], batch["edge_index"], batch["edge_mask"]
        num_robots, num_nodes = nodes.shape[:2]
        # One block-diagonal graph of every ego-graph, one search from every interest node.
        offsets = (np.arange(num_robots) * num_nodes)[:, None, None]
        distance = _distance_to_interest(
            nodes.reshape(-1, nodes.shape[-1]),
            (edge_index + offsets).transpose(1, 0, 2).reshape(2, -1),
            edge_mask.reshape(-1),
            self.hops - 1,
        ).reshape(num_robots, num_nodes)
        move_targets = edge_index[:, 0, 1:5]  # senders of the ego action edges of slots 1-4
        move_distance = np.take_along_axis(distance, move_targets, axis=1)
        return self._choose(move_distance, batch["action_mask"])


class CentralizedGreedyPolicy(_GreedyBase):
    """Centralized greedy on ``env.state()``: the same actions as :class:`GreedyPolicy`.

    Args:
        hops: Horizon K.
        fallback: ``"stay"`` or ``"random"``.
        seed: Seed of the generator of ``fallback="random"``.
    """

    def act_state(self, state: dict[str, Any]) -> np.ndarray:
        """Actions of every robot from the whole-graph state, ``(R,)`` int64 in robot order."""
        distance = _distance_to_interest(
            state["nodes"], state["edge_index"], state["edge_mask"], self.hops - 1
        )
        robots = state["robot_nodes"]
        k = 5 * len(robots)
        move_targets = state["edge_index"][0, :k].reshape(len(robots), 5)[:, 1:]
        return self._choose(distance[move_targets], state["action_mask"])

    def act(self, state: dict[str, Any], agents: list[str]) -> dict[str, int]:
        """Actions keyed by agent name; ``agents`` lists the robots in index order."""
        return dict(zip(agents, self.act_state(state).tolist(), strict=True))


def greedy_return(
    env: Any, hops: int, first: np.ndarray | None = None, compiled: bool | None = None
) -> float:
    """The points greedy visits from a coverage environment's current state to the end of its
    episode (greedy with horizon ``hops``, staying when nothing is within reach; the
    environment is left unchanged): the cheap finish of a rollout's play-outs.

    Args:
        env: A :class:`~marl_cover.env.CoverageEnv` of the coverage task, mid-episode.
        hops: Greedy's horizon K.
        first: ``(R,)`` the first step's action of each robot, ``-1`` for greedy's (default:
            greedy's for all).
        compiled: Play it in the numba kernel (:mod:`marl_cover.agents.baselines._greedy_numba`) or
            on a fork of the environment with :class:`CentralizedGreedyPolicy` (the reference; both
            give the same numbers). ``None``: the kernel where numba is installed.

    Raises:
        ValueError: The environment is not a coverage one, or ``compiled`` without numba.
    """
    compiled = _check_play_out(env, compiled, "greedy_return")
    if not env.agents:
        return 0.0
    num_robots = env.config.num_robots
    first = np.full(num_robots, -1, dtype=np.int64) if first is None else first
    first = np.asarray(first, dtype=np.int64)
    if compiled:
        return _compiled_return(env, env.snapshot(), hops, first)
    fork, policy = env.fork(), CentralizedGreedyPolicy(hops)
    actions = np.where(first >= 0, first, policy.act_state(fork.state()))
    total = float(fork.apply_actions(actions).new_interest.sum())
    while fork.agents:
        total += float(fork.apply_actions(policy.act_state(fork.state())).new_interest.sum())
    return total


def _check_play_out(env: Any, compiled: bool | None, name: str) -> bool:
    """Whether to play in the kernel; refuses a task or a request that cannot be met."""
    if env.config.task != "coverage":
        raise ValueError(f"{name} plays coverage environments, not {env.config.task!r}")
    if compiled is None:
        return _compiled_play_out is not None
    if compiled and _compiled_play_out is None:
        raise ValueError("compiled greedy play-outs need numba installed")
    return compiled


def _compiled_return(env: Any, snapshot: Any, hops: int, first: np.ndarray) -> float:
    """Greedy's return from ``snapshot`` (of ``env``) in the kernel, after ``first``."""
    return float(
        _compiled_play_out(
            snapshot.graph.neighbors,
            snapshot.robot_node,
            snapshot.interest & ~snapshot.visited,
            snapshot.max_steps - snapshot.num_steps,
            hops,
            env.config.allow_swaps,
            first,
        )
    )
