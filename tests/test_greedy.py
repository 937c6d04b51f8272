"""Greedy baseline: exact choices on tiny graphs, decentralized == centralized, golden numbers."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_grid_graph

import marl_cover
from marl_cover.agents.baselines.greedy import (
    CentralizedGreedyPolicy,
    GreedyPolicy,
    greedy_return,
)

STAY, EAST, NORTH, WEST, SOUTH = range(5)


def test_moves_toward_the_nearest_point(tee_graph) -> None:
    env = marl_cover.parallel_env(graph=tee_graph, num_robots=1, hops=3)
    obs, _ = env.reset(seed=0, options={"robot_nodes": [1], "interest_nodes": [3, 5]})
    # from waypoint 1: 3 is two hops east, 5 two hops north: tie -> lowest slot (east)
    assert GreedyPolicy(3).act(obs) == {"robot_0": EAST}
    obs, _ = env.reset(seed=0, options={"robot_nodes": [1], "interest_nodes": [3, 4]})
    assert GreedyPolicy(3).act(obs) == {"robot_0": NORTH}


def test_horizon_and_fallback(path_graph) -> None:
    env = marl_cover.parallel_env(graph=path_graph, num_robots=1, hops=7)
    obs, _ = env.reset(seed=0, options={"robot_nodes": [3], "interest_nodes": [7]})
    assert GreedyPolicy(4).act(obs) == {"robot_0": EAST}  # 4 hops away: in reach
    assert GreedyPolicy(3).act(obs) == {"robot_0": STAY}  # out of reach: stay
    moves = {GreedyPolicy(3, fallback="random", seed=s).act(obs)["robot_0"] for s in range(20)}
    assert moves == {EAST, WEST}
    state = env.state()
    assert CentralizedGreedyPolicy(4).act_state(state).tolist() == [EAST]
    assert CentralizedGreedyPolicy(3).act_state(state).tolist() == [STAY]


def test_rejects_bad_arguments() -> None:
    with pytest.raises(ValueError, match="fallback"):
        GreedyPolicy(3, fallback="teleport")
    with pytest.raises(ValueError, match="hops"):
        GreedyPolicy(0)


@pytest.mark.parametrize(("hops", "fallback"), [(2, "random"), (6, "stay"), (19, "random")])
def test_centralized_gives_the_same_actions(hops: int, fallback: str) -> None:
    env = marl_cover.parallel_env(num_robots=6, hops=hops, city_size=300)
    local = GreedyPolicy(hops, fallback=fallback, seed=1)
    central = CentralizedGreedyPolicy(hops, fallback=fallback, seed=1)
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        while env.agents:
            actions = local.act(obs)
            assert actions == central.act(env.state(), env.possible_agents)
            obs, *_ = env.step(actions)


@pytest.mark.parametrize("allow_swaps", [True, False])
def test_compiled_greedy_play_outs_equal_the_environments(allow_swaps: bool) -> None:
    """Crowded random grids (up to 12 robots, on at least twice as many waypoints: blocked
    moves, chains and swaps), some first moves forced (masked ones included): the kernel's
    return is the environment's, step for step, and the environment is left alone."""
    pytest.importorskip("numba")
    rng = np.random.default_rng(7)
    totals = []
    for seed in range(25):
        graph = random_grid_graph(rng, 8, 8, density=0.7)
        while graph.num_nodes < 20:
            graph = random_grid_graph(rng, 8, 8, density=0.7)
        num_robots = int(rng.integers(2, min(13, graph.num_nodes // 2)))
        env = marl_cover.parallel_env(
            graph=graph,
            num_robots=num_robots,
            hops=int(rng.integers(1, 10)),
            max_steps=int(rng.integers(1, 25)),
            interest_fraction=0.6,
            allow_swaps=allow_swaps,
        )
        env.reset(seed=seed)
        for _ in range(int(rng.integers(0, 3))):
            env.apply_actions(rng.integers(0, 5, size=num_robots))
        before = env.state()
        for first in (None, rng.integers(-1, 5, size=num_robots)):
            hops = env.config.hops
            compiled = greedy_return(env, hops, first, compiled=True)
            assert compiled == greedy_return(env, hops, first, compiled=False)
            totals.append(compiled)
        for key, value in before.items():
            np.testing.assert_array_equal(env.state()[key], value)
    assert len(set(totals)) > 5  # the cases differ


def test_greedy_return_names_an_exploration_environment() -> None:
    env = marl_cover.parallel_env(task="exploration", num_robots=2, hops=3, city_size=200)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="plays coverage environments, not 'exploration'"):
        greedy_return(env, 3)


def greedy_returns(seeds, **config) -> list[float]:
    env = marl_cover.parallel_env(**config)
    returns = []
    for seed in seeds:
        policy = GreedyPolicy(env.config.hops, fallback="random", seed=seed)
        obs, _ = env.reset(seed=seed)
        total = 0.0
        while env.agents:
            obs, rewards, *_ = env.step(policy.act(obs))
            total += rewards["robot_0"]
        returns.append(total)
    return returns


def test_golden_returns_on_the_city() -> None:
    assert greedy_returns(range(5)) == GOLDEN_CITY


def test_golden_returns_on_paper_windows(paper_map_available) -> None:
    assert greedy_returns(range(5), map="paper") == GOLDEN_PAPER


# Fixed by running the current code once (greedy, K = 19, 4 robots, T = 50, random fallback).
GOLDEN_CITY = [71.0, 85.0, 57.0, 75.0, 81.0]
GOLDEN_PAPER = [96.0, 76.0, 55.0, 76.0, 61.0]
