"""Omniscient assignment: exact choices on tiny graphs, distinct points, golden numbers."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_grid_graph

import marl_cover
from marl_cover.agents.baselines.assignment import AssignmentPolicy
from marl_cover.agents.baselines.greedy import CentralizedGreedyPolicy
from marl_cover.agents.evaluation.bounds import episode_bound
from marl_cover.agents.evaluation.episodes import run_episode

STAY, EAST, NORTH, WEST, SOUTH = range(5)


def _actions(env, policy, robots: list[int], interest: list[int]) -> list[int]:
    env.reset(seed=0, options={"robot_nodes": robots, "interest_nodes": interest})
    return list(policy.act_env(env).values())


def test_robots_split_between_points(path_graph) -> None:
    env = marl_cover.parallel_env(graph=path_graph, num_robots=2, hops=7)
    # greedy sends both robots east to 5 (the nearest point of each)
    env.reset(seed=0, options={"robot_nodes": [3, 4], "interest_nodes": [0, 5]})
    assert CentralizedGreedyPolicy(7).act_state(env.state()).tolist() == [EAST, EAST]
    # matched: 3 -> 0 and 4 -> 5 (4 hops in all) beats 3 -> 5 and 4 -> 0 (6 hops)
    policy = AssignmentPolicy(far_weight=0.0)
    assert _actions(env, policy, [3, 4], [0, 5]) == [WEST, EAST]


def test_far_points_weighted_up(path_graph) -> None:
    env = marl_cover.parallel_env(graph=path_graph, num_robots=1, hops=7)
    # from 3: the point at 2 is one hop away, the one at 7 four hops (and four from the start)
    assert _actions(env, AssignmentPolicy(far_weight=0.0), [3], [2, 7]) == [WEST]
    assert _actions(env, AssignmentPolicy(far_weight=2.0), [3], [2, 7]) == [EAST]


def test_nothing_in_reach_moves_at_random(path_graph) -> None:
    env = marl_cover.parallel_env(graph=path_graph, num_robots=1, hops=7)
    moves = {_actions(env, AssignmentPolicy(horizon=2, seed=s), [3], [7])[0] for s in range(20)}
    assert moves == {EAST, WEST}
    assert _actions(env, AssignmentPolicy(horizon=4), [3], [7]) == [EAST]
    assert _actions(env, AssignmentPolicy(), [0], [7]) == [EAST]  # the only legal move


def test_matched_points_are_distinct_and_bounded() -> None:
    rng = np.random.default_rng(5)
    graph = random_grid_graph(rng, 16, 16, 0.8)
    env = marl_cover.parallel_env(graph=graph, num_robots=12, hops=4, max_steps=15)
    policy = AssignmentPolicy(candidates=3)
    for seed in range(4):
        env.reset(seed=seed)
        snapshot = env.snapshot()
        policy.act_env(env)  # the team's start distances
        target, first, score = policy._candidates(
            graph.adjacency, snapshot.robot_node, snapshot.interest & ~snapshot.visited, 15
        )
        chosen = policy._match(target, score)
        points = target[np.flatnonzero(chosen >= 0), chosen[chosen >= 0]]
        assert len(points) == len(set(points.tolist())) > 0
        assert run_episode(env, policy, seed).reward <= episode_bound(env, seed, "route")


def test_rejects_bad_arguments() -> None:
    for kwargs, message in (
        ({"horizon": 0}, "horizon must be >= 1"),
        ({"candidates": 0}, "candidates must be >= 1"),
        ({"far_weight": -1.0}, "far_weight >= 0"),
    ):
        with pytest.raises(ValueError, match=message):
            AssignmentPolicy(**kwargs)


def test_golden_on_a_city() -> None:
    env = marl_cover.parallel_env(num_robots=100, map="city", city_size=5659, max_steps=50)
    rewards = [run_episode(env, AssignmentPolicy(), seed).reward for seed in range(2)]
    assert rewards == [869.0, 903.0]
