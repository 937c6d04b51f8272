"""Bad input to the environment: a clear error that names it, and nothing changed.

A reset that raises leaves the environment exactly as it was (its generator included): the
episode in progress goes on as if the reset had never been called, and an environment that
never started stays unsteppable.
"""

from __future__ import annotations

import numpy as np
import pytest

import marl_cover
from marl_cover.graph import SpatialGraph


def two_islands() -> SpatialGraph:
    """A 2x3 lattice (waypoints 0-5) and, apart from it, a pair (6, 7)."""
    positions = [[x, y] for y in (0, 1) for x in (0, 1, 2)] + [[10, 0], [11, 0]]
    edges = [(0, 1), (1, 2), (3, 4), (4, 5), (0, 3), (1, 4), (2, 5), (6, 7)]
    return SpatialGraph.from_edges(np.array(positions, float), edges)


def actions_for(env, step: int) -> dict[str, int]:
    """A fixed legal action per robot: its first legal move in a rotating order."""
    obs = env.observations()
    out = {}
    for i, agent in enumerate(env.agents):
        legal = np.flatnonzero(obs[agent]["action_mask"])
        out[agent] = int(legal[(step + i) % len(legal)])
    return out


def play(env, steps: int) -> list:
    """Rewards and observations of ``steps`` steps of :func:`actions_for`."""
    trace = []
    for t in range(steps):
        if not env.agents:
            break
        obs, rewards, *_ = env.step(actions_for(env, t))
        trace.append((rewards, {a: {k: v.tolist() for k, v in o.items()} for a, o in obs.items()}))
    return trace


BAD_RESETS = [
    pytest.param({"seed": -1}, "seed must be a non-negative integer", id="negative-seed"),
    pytest.param({"seed": 1.5}, "seed must be a non-negative integer", id="float-seed"),
    pytest.param(
        {"options": {"robot_nodes": [0, 0, 1, 2]}}, "must hold 4 distinct", id="shared-start"
    ),
    pytest.param({"options": {"robot_nodes": [0, 1, 2]}}, "must hold 4 distinct", id="3-starts"),
    pytest.param(
        {"options": {"robot_nodes": [0, 1, 2, 10**6]}},
        r"options\['robot_nodes'\] holds a waypoint outside \[0, \d+\): entry 3 is 1000000",
        id="start-off-map",
    ),
    pytest.param(
        {"options": {"robot_nodes": [0.0, 0.9, 2.0, 3.0]}},
        r"options\['robot_nodes'\] must hold integer indices, got float64 values; entry 1 is 0.9",
        id="float-starts",
    ),
    pytest.param(
        {"options": {"interest_nodes": [5, -2]}},
        r"options\['interest_nodes'\] holds a waypoint outside .*: entry 1 is -2",
        id="interest-off-map",
    ),
    pytest.param(
        {"options": {"interest_nodes": ["a"]}},
        r"options\['interest_nodes'\] must hold integer indices",
        id="string-interest",
    ),
]


@pytest.mark.parametrize("task", ["coverage", "exploration"])
@pytest.mark.parametrize(("reset_args", "message"), BAD_RESETS)
def test_failed_reset_changes_nothing(task: str, reset_args: dict, message: str) -> None:
    """After a failed reset mid-episode, the episode goes on bit for bit as in a twin that
    never saw it, and the next seedless reset draws what the twin's draws."""
    config = {"map": "city", "city_size": 80, "num_robots": 4, "task": task, "max_steps": 12}
    env, twin = marl_cover.parallel_env(**config), marl_cover.parallel_env(**config)
    for e in (env, twin):
        e.reset(seed=7)
    assert play(env, 3) == play(twin, 3)
    with pytest.raises(ValueError, match=message):
        env.reset(**reset_args)
    assert env.agents == twin.agents
    assert play(env, 20) == play(twin, 20)  # the old episode, to its end
    first, second = env.reset(), twin.reset()  # the generator was not advanced
    assert first[0].keys() == second[0].keys()
    for agent in first[0]:
        for key in first[0][agent]:
            np.testing.assert_array_equal(first[0][agent][key], second[0][agent][key])
    assert play(env, 5) == play(twin, 5)


def test_failed_first_reset_leaves_env_unsteppable() -> None:
    env = marl_cover.parallel_env(map="city", city_size=80, num_robots=4)
    with pytest.raises(ValueError, match="distinct"):
        env.reset(seed=0, options={"robot_nodes": [0, 0, 1, 2]})
    assert env.agents == []
    with pytest.raises(RuntimeError, match="call reset"):
        env.step({a: 0 for a in env.possible_agents})
    with pytest.raises(RuntimeError, match="call reset"):
        env.state()


def test_failed_map_check_in_reset_changes_nothing() -> None:
    """A check of the drawn map (the quadrotor env's arrival radius against the cell size)
    fails before the episode changes."""
    graph = SpatialGraph.from_edges(np.array([[0.0, 0], [1, 0], [2, 0]]), [(0, 1), (1, 2)])
    env = marl_cover.quadrotor_parallel_env(
        graph=graph, num_robots=1, dynamics={"arrival_radius": 2.0}
    )
    with pytest.raises(ValueError, match="arrival_radius 2.0 m exceeds half the map's cell size"):
        env.reset(seed=0)
    assert env.agents == []
    with pytest.raises(RuntimeError, match="call reset"):
        env.step({"robot_0": 0})


def test_team_larger_than_a_component_is_rejected_when_built() -> None:
    """Two robots fit on either island; three do not fit on the pair, whatever the seed."""
    env = marl_cover.parallel_env(graph=two_islands(), num_robots=2)
    for seed in range(20):
        env.reset(seed=seed)
    with pytest.raises(
        ValueError,
        match=r"a connected component of 2 waypoints \(waypoint 6 is in it\), smaller than "
        r"the team of 3 robots",
    ):
        marl_cover.parallel_env(graph=two_islands(), num_robots=3)


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (np.nan, r"positions must be finite; entry 2 is \[nan, 0.0\]"),
        (np.inf, r"positions must be finite; entry 2 is \[inf, 0.0\]"),
    ],
)
def test_non_finite_positions_are_rejected(value: float, message: str) -> None:
    positions = np.array([[0.0, 0], [1, 0], [value, 0]])
    with pytest.raises(ValueError, match=message):
        SpatialGraph.from_edges(positions, [(0, 1), (1, 2)])
    with pytest.raises(ValueError, match=message):
        SpatialGraph(positions, np.full((3, 4), -1))


def test_non_integer_indices_are_rejected() -> None:
    positions = np.array([[0.0, 0], [1, 0], [2, 0]])
    with pytest.raises(
        ValueError, match=r"edges must hold integer indices.* entry \(1, 0\) is 1.5"
    ):
        SpatialGraph.from_edges(positions, np.array([[0, 1], [1.5, 2]]))
    neighbors = np.full((3, 4), -1.0)
    with pytest.raises(ValueError, match="neighbors must hold integer indices, got float64"):
        SpatialGraph(positions, neighbors)
    with pytest.raises(
        ValueError, match=r"neighbors must hold integer indices; entry \(0, 0\) is True"
    ):
        SpatialGraph(positions, np.array([True, -1, -1, -1] * 3, dtype=object).reshape(3, 4))
