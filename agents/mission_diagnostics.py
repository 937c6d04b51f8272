"""What a mission policy does with each decision, by what the deciding robot can see.

:class:`DecisionRecorder` wraps a policy that decides from the robots' ego-observations (greedy,
the decentralized GNN) and sorts every decision of a ready robot two ways:

- *in view* or *blind*: whether the robot's ego-graph holds a target (an unvisited point of
  interest, or in exploration a frontier waypoint; the targets of greedy's rule);
- *stay* (action 0), *back* (a move to the waypoint the robot was at before its current one)
  or *forward* (any other move).

A deterministic policy that goes back on most of its blind decisions oscillates between two
waypoints until something comes into view. ``blind`` swaps the policy's own blind decisions for
another rule, to measure what they cost: ``"random"``, a uniformly random available move (the
paper's greedy fallback), ``"sample"``, a draw from the GNN's own distribution instead of its
argmax (both use the recorder's generator, reset with each mission's seed), or ``"nearest"``,
one hop along a shortest path to the nearest unvisited point of interest anywhere on the map
(knowledge of the whole map that no ego-graph holds: what such knowledge is at most worth to
a blind robot; the lowest action slot on ties, masked moves skipped, stay when no point is
left or no move is available).

The recorder is as deterministic as its policy with ``blind="policy"``, and counts as not
deterministic otherwise (the moves are random, or ``"nearest"`` reads beyond the robots' view),
so :func:`agents.mission.run_mission` skips asking again while nothing the robots see has
changed exactly when it would for the policy alone, and a mission with ``blind="policy"`` is
the policy's own mission.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np

from agents.greedy import TARGET_COLUMNS
from marl_cover.continuous import QuadrotorCoverageEnv

KINDS = ("stay", "back", "forward")
BLIND_RULES = ("policy", "random", "sample", "nearest")


def target_in_view(observation: dict[str, np.ndarray]) -> bool:
    """Whether a robot's ego-observation holds an unvisited point of interest or a frontier."""
    real = observation["node_mask"].astype(bool)  # (max_nodes,)
    return bool(observation["nodes"][real][:, TARGET_COLUMNS].any())


class DecisionRecorder:
    """A policy with ``act(observations)``, its decisions counted (see the module docstring).

    Args:
        policy: The wrapped policy (its ``reset(seed)`` is called when present).
        env: The environment it flies in (for the robots' snapped waypoints and the graph).
        blind: What a blind robot does: ``"policy"`` (the policy's own action), ``"random"``,
            ``"sample"`` (a :class:`agents.models.policy.GNNPolicy` only) or ``"nearest"``.
        seed: Seed of the generator of blind moves (reset with each mission's seed).

    Attributes:
        counts: ``(in_view, kind) -> decisions`` over every mission flown since creation.

    Raises:
        ValueError: an unknown ``blind`` rule, or ``"sample"`` for a policy without logits.
    """

    def __init__(
        self, policy: Any, env: QuadrotorCoverageEnv, blind: str = "policy", seed: int = 0
    ) -> None:
        if blind not in BLIND_RULES:
            raise ValueError(f"unknown blind rule {blind!r}; choose from {BLIND_RULES}")
        if blind == "sample" and not hasattr(policy, "logits"):
            raise ValueError(
                f"blind='sample' draws from a GNN's distribution; {type(policy).__name__} "
                "has no logits"
            )
        self.policy, self.env, self.blind = policy, env, blind
        self.counts: Counter[tuple[bool, str]] = Counter()
        self._rng = np.random.default_rng(seed)
        self._index = {agent: i for i, agent in enumerate(env.possible_agents)}
        self._current = np.full(len(env.possible_agents), -1)  # (num_robots,)
        self._previous = np.full(len(env.possible_agents), -1)  # (num_robots,)
        self._neighbors: np.ndarray | None = None  # (num_nodes, 4) of this mission's graph

    @property
    def deterministic(self) -> bool:
        """Whether the same observations give the same actions (see the module docstring)."""
        return self.blind == "policy" and getattr(self.policy, "deterministic", True)

    def reset(self, seed: int | None = None) -> None:
        """Starts a mission: forgets where the robots were; reseeds the blind moves."""
        if hasattr(self.policy, "reset"):
            self.policy.reset(seed)
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self._current[:] = -1
        self._previous[:] = -1
        self._neighbors = None  # the env is reset after the policy: read at the first decision

    def act(self, observations: dict[str, dict[str, np.ndarray]]) -> dict[str, int]:
        """The policy's actions (blind ones replaced by the ``blind`` rule), counted."""
        actions = dict(self.policy.act(observations))
        blind = {agent for agent in observations if not target_in_view(observations[agent])}
        if self.blind != "policy" and blind:
            actions.update(self._blind_moves({agent: observations[agent] for agent in blind}))
        if self._neighbors is None:
            self._neighbors = self.env.snapshot().graph.neighbors
        for agent in observations:
            action, robot = actions[agent], self._index[agent]
            node = int(self.env.snapped[robot])
            if node != self._current[robot]:
                self._previous[robot], self._current[robot] = self._current[robot], node
            if action == 0:
                kind = "stay"
            elif self._neighbors[node, action - 1] == self._previous[robot]:
                kind = "back"
            else:
                kind = "forward"
            self.counts[(agent not in blind, kind)] += 1
        return actions

    def _blind_moves(self, observations: dict[str, dict[str, np.ndarray]]) -> dict[str, int]:
        if self.blind == "nearest":
            return self._nearest_moves(observations)
        if self.blind == "random":
            moves = {}
            for agent, observation in observations.items():
                available = np.flatnonzero(observation["action_mask"][1:]) + 1
                moves[agent] = int(self._rng.choice(available)) if len(available) else 0
            return moves
        logits = self.policy.logits(observations).double().numpy()  # (blind robots, 5)
        probs = np.exp(logits - logits.max(axis=1, keepdims=True))
        probs /= probs.sum(axis=1, keepdims=True)
        return {
            agent: int(self._rng.choice(len(p), p=p))
            for agent, p in zip(observations, probs, strict=True)
        }

    def _nearest_moves(self, observations: dict[str, dict[str, np.ndarray]]) -> dict[str, int]:
        """One hop toward the nearest unvisited point of interest on the whole map."""
        snapshot = self.env.snapshot()
        # (num_nodes,) hops to the nearest target; all inf when none is left (every robot stays)
        distance = snapshot.graph.nearest_distance(np.flatnonzero(snapshot.unvisited_interest))
        moves = {}
        for agent, observation in observations.items():
            neighbors = snapshot.graph.neighbors[int(self.env.snapped[self._index[agent]])]
            reach = np.where(  # (4,) hops to a target from each available neighbour
                (neighbors >= 0) & observation["action_mask"][1:].astype(bool),
                distance[np.maximum(neighbors, 0)],
                np.inf,
            )
            moves[agent] = int(np.argmin(reach)) + 1 if np.isfinite(reach).any() else 0
        return moves

    def table(self) -> dict[str, dict[str, int]]:
        """``{"in view" | "blind": {kind: decisions}}``."""
        return {
            label: {kind: self.counts[(in_view, kind)] for kind in KINDS}
            for label, in_view in (("in view", True), ("blind", False))
        }
