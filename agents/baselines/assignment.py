"""Omniscient assignment: each step, robots matched to distinct points of interest.

A centralized reference for large teams, where the routing experts do not scale: it reads the
whole map (points of interest not yet discovered included, as the experts do) and, each step,

1. lists for every robot its ``candidates`` best points of interest within ``horizon`` hops
   (breadth-first search from each robot, :func:`scipy.sparse.csgraph.dijkstra`), scored by
   ``hops - far_weight * start_hops``: near points first, points far from the team's start
   (which only robots that head out at once still reach) weighted up;
2. matches robots to distinct points at the least total score
   (:func:`scipy.sparse.csgraph.min_weight_full_bipartite_matching`), so no two robots chase
   one point;
3. moves each robot one hop along a shortest path to its point; a robot left without one moves
   at random (greedy's fallback).

Cost a step: one search of ``horizon`` hops per robot and a sparse matching of ``R x
candidates`` pairs (about 0.25 s at 1000 robots on a 56,590-waypoint city).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import dijkstra, min_weight_full_bipartite_matching

#: Robots searched at once (two ``(chunk, num_waypoints)`` arrays).
_CHUNK = 128


class AssignmentPolicy:
    """Robots matched to distinct points of interest each step (the module docstring).

    Args:
        horizon: Search radius in hops (``None``: the moves left in the episode).
        candidates: Points listed per robot for the matching.
        far_weight: Weight of a point's distance from the team's start in its score.
        seed: Seed of the random fallback moves (re-seeded by :meth:`reset`).
    """

    def __init__(
        self,
        horizon: int | None = None,
        candidates: int = 8,
        far_weight: float = 0.5,
        seed: int = 0,
    ) -> None:
        if horizon is not None and horizon < 1:
            raise ValueError(f"horizon must be >= 1 or None, got {horizon}")
        if candidates < 1 or far_weight < 0:
            raise ValueError(
                f"candidates must be >= 1 and far_weight >= 0, got {candidates}, {far_weight}"
            )
        self.horizon, self.candidates, self.far_weight = horizon, candidates, far_weight
        self.reset(seed)

    def reset(self, seed: int) -> None:
        """Re-seeds the fallback moves; the next step is taken as an episode's first."""
        self._rng = np.random.default_rng(seed)
        self._start_hops: np.ndarray | None = None  # (N,) hops from the team's start

    def act_env(self, env: Any) -> dict[str, int]:
        """Actions keyed by agent name, from ``env.snapshot()``."""
        snapshot = env.snapshot()
        graph, robot = snapshot.graph, snapshot.robot_node  # (R,)
        if snapshot.num_steps == 0 or self._start_hops is None:
            hops = dijkstra(graph.adjacency, indices=robot, unweighted=True, min_only=True)
            self._start_hops = np.where(np.isfinite(hops), hops, 0.0)  # (N,)
        steps_left = snapshot.max_steps - snapshot.num_steps
        radius = steps_left if self.horizon is None else min(self.horizon, steps_left)
        open_interest = snapshot.interest & ~snapshot.visited  # (N,)
        target, first, score = self._candidates(graph.adjacency, robot, open_interest, radius)
        chosen = self._match(target, score)  # (R,) a column of target and first, -1: none
        neighbors = graph.neighbors[robot]  # (R, 4)
        action = self._random_moves(neighbors)  # (R,)
        matched = np.flatnonzero(chosen >= 0)
        step = first[matched, chosen[matched]]  # (M,) the next waypoint
        slot = np.argmax(neighbors[matched] == step[:, None], axis=1)
        action[matched] = slot + 1
        return dict(zip(env.possible_agents, action.tolist(), strict=True))

    def _candidates(
        self, adjacency: sparse.spmatrix, robot: np.ndarray, open_interest: np.ndarray, radius: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each robot's candidate points ``(R, C)`` (``-1``: none), the first waypoint on a
        shortest path to each ``(R, C)``, and their scores ``(R, C)``."""
        num_robots, count = len(robot), self.candidates
        target = np.full((num_robots, count), -1, dtype=np.int64)
        first = np.full((num_robots, count), -1, dtype=np.int64)
        scores = np.zeros((num_robots, count))
        assert self._start_hops is not None
        for start in range(0, num_robots, _CHUNK):
            rows = slice(start, start + _CHUNK)
            hops, parent = dijkstra(
                adjacency,
                indices=robot[rows],
                unweighted=True,
                limit=radius,
                return_predecessors=True,
            )  # (c, N) each
            row, point = np.nonzero(np.isfinite(hops) & open_interest)  # (M,) each
            score = hops[row, point] - self.far_weight * self._start_hops[point]
            order = np.lexsort((point, score, row))  # by robot, then score, then point
            row, point, score = row[order], point[order], score[order]
            rank = np.arange(len(row)) - np.searchsorted(row, row)  # within the robot's row
            keep = rank < count
            target[start + row[keep], rank[keep]] = point[keep]
            scores[start + row[keep], rank[keep]] = score[keep]
            first[rows] = _first_steps(parent, robot[rows], target[rows])
        return target, first, scores

    def _match(self, target: np.ndarray, score: np.ndarray) -> np.ndarray:
        """The column of ``target`` ``(R, C)`` each robot is matched to ``(R,)`` at the least
        total ``score`` ``(R, C)``, ``-1`` for none."""
        num_robots = len(target)
        robot, column = np.nonzero(target >= 0)
        chosen = np.full(num_robots, -1, dtype=np.int64)
        if len(robot) == 0:
            return chosen
        points, point_id = np.unique(target[robot, column], return_inverse=True)
        scores = score[robot, column]
        cost = scores - scores.min() + 1.0  # > 0: a stored zero would be no edge
        unmatched = cost.max() + 1.0  # each robot's own way out, dearer than any point
        weights = sparse.csr_matrix(
            (
                np.concatenate([cost, np.full(num_robots, unmatched)]),
                (
                    np.concatenate([robot, np.arange(num_robots)]),
                    np.concatenate([point_id, len(points) + np.arange(num_robots)]),
                ),
            ),
            shape=(num_robots, len(points) + num_robots),
        )
        rows, columns = min_weight_full_bipartite_matching(weights)
        point_of = np.full(num_robots, -1, dtype=np.int64)
        point_of[rows] = np.where(columns < len(points), columns, -1)
        matched = point_of[robot] == point_id
        chosen[robot[matched]] = column[matched]
        return chosen

    def _random_moves(self, neighbors: np.ndarray) -> np.ndarray:
        """A random legal move of each robot ``(R,)`` (stay where it has no neighbour)."""
        valid = neighbors >= 0  # (R, 4)
        draw = self._rng.random(neighbors.shape)
        slot = np.argmax(np.where(valid, draw, -1.0), axis=1)
        return np.where(valid.any(axis=1), slot + 1, 0)


def _first_steps(parent: np.ndarray, origin: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The first waypoint of the shortest path from ``origin[i]`` to each ``target[i, c]``
    ``(c, C)`` by the predecessors ``parent`` ``(c, N)`` of a search from each origin (``-1``
    where the target is ``-1``)."""
    node = target.copy()
    row = np.broadcast_to(np.arange(len(origin))[:, None], target.shape)
    active = node >= 0
    while True:
        previous = np.where(active, parent[row, np.maximum(node, 0)], -1)
        active &= previous != origin[:, None]
        if not active.any():
            return node
        node = np.where(active, previous, node)
