"""Quadrotor bodies, their controller, and the continuous-time coverage environment."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
from helpers import random_grid_graph
from pettingzoo.test import parallel_api_test, parallel_seed_test

import marl_cover
from marl_cover.continuous import DynamicsConfig, QuadrotorCoverageEnv
from marl_cover.dynamics import QuadrotorParams, QuadrotorTeam
from marl_cover.locator import WaypointLocator


def fly(params: QuadrotorParams, target: np.ndarray, seconds: float, **team_kwargs) -> dict:
    team = QuadrotorTeam(params, np.zeros((1, 3)), **team_kwargs)
    steps = round(seconds / params.dt)
    track = np.empty((steps, 1, 3))
    speeds, accels = [], []
    for k in range(steps):
        team.step(target[None])
        track[k] = team.position
        speeds.append(np.linalg.norm(team.velocity))
        accels.append(np.linalg.norm(team.acceleration))
    return {"track": track[:, 0], "speed": np.array(speeds), "accel": np.array(accels)}


# ---------------------------------------------------------------------- the controller
@pytest.mark.parametrize("drag", [0.0, 0.25, 2.0])
def test_controller_reaches_the_target_within_its_limits(drag: float) -> None:
    params = QuadrotorParams(drag=drag, max_speed=2.0, max_accel=3.0)
    target = np.array([20.0, -5.0, 4.0])
    out = fly(params, target, seconds=30.0)
    assert np.linalg.norm(out["track"][-1] - target) < 0.01
    assert out["speed"].max() <= 2.0 + 1e-12
    assert out["accel"].max() <= 3.0 + 1e-12
    # The limits are reached on the way (the 21 m flight is long enough); strong drag caps the
    # speed where it eats the whole acceleration: terminal speed max_accel * mass / drag.
    top = min(2.0, 3.0 * params.mass / drag) if drag else 2.0
    assert top - 1e-3 < out["speed"].max() and out["accel"].max() > 2.99
    # At 2 m/s, 21 m take at least 10.5 s: the body is still short of the target at 10 s.
    assert np.linalg.norm(out["track"][999] - target) > 0.5


def test_ideal_dynamics_move_in_one_step_and_stop() -> None:
    params = QuadrotorParams.ideal(dt=0.01)
    out = fly(params, np.array([5.0, 0.0, 3.0]), seconds=0.05)
    np.testing.assert_allclose(out["track"], np.tile([5.0, 0.0, 3.0], (5, 1)), atol=1e-9)
    assert out["speed"][1:].max() < 1e-9


def test_actuation_delay_holds_the_old_target() -> None:
    params = QuadrotorParams()
    out = fly(params, np.array([5.0, 0.0, 0.0]), seconds=1.0, delay=0.3)
    assert np.all(out["track"][:30] == 0.0)  # the first 30 steps still track the start
    assert out["track"][31, 0] > 0.0


def test_measurement_noise_is_seeded() -> None:
    params = QuadrotorParams()
    target = np.array([5.0, 0.0, 0.0])
    a = fly(params, target, 2.0, noise_std=0.1, rng=np.random.default_rng(3))
    b = fly(params, target, 2.0, noise_std=0.1, rng=np.random.default_rng(3))
    clean = fly(params, target, 2.0)
    assert np.array_equal(a["track"], b["track"])
    assert not np.array_equal(a["track"], clean["track"])


@pytest.mark.parametrize(
    ("drag", "max_speed", "noise_std", "delay"),
    [
        (0.25, 2.0, 0.0, 0.0),
        (0.0, math.inf, 0.0, 0.0),
        (2.0, 2.0, 0.05, 0.0),
        (0.25, 2.0, 0.05, 0.2),
    ],
)
def test_compiled_dynamics_give_the_reference_bits(
    drag: float, max_speed: float, noise_std: float, delay: float
) -> None:
    pytest.importorskip("numba")
    params = QuadrotorParams(drag=drag, max_speed=max_speed, max_accel=3.0)
    rng = np.random.default_rng(7)
    start = rng.uniform(-10, 10, (6, 3))
    teams = [
        QuadrotorTeam(params, start, noise_std, delay, np.random.default_rng(1), backend=b)
        for b in ("numpy", "numba")
    ]
    for period in range(40):  # periods of 0..13 steps, with and without a track
        targets, steps = rng.uniform(-20, 20, (6, 3)), int(rng.integers(0, 14))
        tracks = [np.full((steps, 6, 3), np.nan) for _ in teams]
        for team, track in zip(teams, tracks, strict=True):
            team.advance(targets, steps, track if period % 2 else None)
        reference, compiled = teams
        for name in ("position", "velocity", "acceleration"):
            assert np.array_equal(getattr(reference, name), getattr(compiled, name)), name
        assert np.array_equal(tracks[0], tracks[1], equal_nan=True)
        assert np.array_equal(reference.measure(), compiled.measure())  # same noise stream
    with pytest.raises(ValueError, match="dynamics backend must be one of"):
        QuadrotorTeam(params, start, backend="fortran")
    with pytest.raises(ValueError, match="DynamicsConfig: backend must be one of"):
        DynamicsConfig(backend="fortran")


def test_bad_parameters_are_named() -> None:
    with pytest.raises(ValueError, match="max_speed"):
        QuadrotorParams(max_speed=0.0)
    with pytest.raises(ValueError, match="velocity_gain"):
        QuadrotorParams(velocity_gain=200.0, dt=0.01)
    with pytest.raises(ValueError, match="control_period"):
        DynamicsConfig(control_period=0.015)
    with pytest.raises(TypeError, match="unknown QuadrotorParams key.*'mas'"):
        DynamicsConfig.from_dict({"quadrotor": {"mas": 1.0}})
    with pytest.raises(ValueError, match="noise_std and delay"):
        QuadrotorTeam(QuadrotorParams(), np.zeros((1, 3)), noise_std=-1.0)
    with pytest.raises(TypeError, match="QuadrotorParams.mass must be a number, got 'heavy'"):
        DynamicsConfig.from_dict({"quadrotor": {"mass": "heavy"}})
    with pytest.raises(TypeError, match=r"DynamicsConfig.altitude_range must be tuple"):
        DynamicsConfig(altitude_range=(3.0, "high"))
    assert DynamicsConfig(altitude_range=[3, 8], max_time=400).altitude_range == (3.0, 8.0)
    with pytest.raises(TypeError, match="dynamics must be a DynamicsConfig or a dict.*'fast'"):
        marl_cover.quadrotor_parallel_env(map="city", dynamics="fast")


# ---------------------------------------------------------------------- snapping
def test_locator_matches_a_kd_tree_on_and_off_the_lattice() -> None:
    rng = np.random.default_rng(0)
    lattice = random_grid_graph(rng, 12, 15, 0.3)
    points = rng.uniform(-10, 90, size=(500, 2))
    shifted = lattice.positions.copy()
    shifted[0] += [0.3, 0.0]  # one waypoint off the lattice: the k-d tree answers everything
    off_lattice = marl_cover.SpatialGraph(shifted, lattice.neighbors, lattice.cell_size)
    backends = ("numpy", "numba") if importlib.util.find_spec("numba") else ("numpy",)
    for graph in (lattice, off_lattice):
        found = {b: WaypointLocator(graph, b).nearest(points) for b in backends}
        node, dist = found["numpy"]
        truth = np.linalg.norm(points[:, None] - graph.positions[None], axis=-1)
        np.testing.assert_allclose(dist, truth.min(axis=1), atol=1e-9)
        assert np.all(truth[np.arange(len(points)), node] <= truth.min(axis=1) + 1e-9)
        for other_node, other_dist in found.values():  # the compiled lookup: the same bits
            assert np.array_equal(other_node, node) and np.array_equal(other_dist, dist)


# ---------------------------------------------------------------------- the environment
def line_env(path_graph, num_robots: int = 1, **dynamics) -> QuadrotorCoverageEnv:
    return QuadrotorCoverageEnv(graph=path_graph, num_robots=num_robots, dynamics=dynamics)


def test_arrival_mode_flies_one_edge_per_step_and_visits_on_the_way(path_graph) -> None:
    env = line_env(path_graph, visit_radius=1.0)
    obs, infos = env.reset(seed=0, options={"robot_nodes": [0], "interest_nodes": [1, 2, 5]})
    assert infos["robot_0"]["ready"] and infos["robot_0"]["time"] == 0.0
    _, rewards, _, _, infos = env.step({"robot_0": 1})  # east
    info = infos["robot_0"]
    assert rewards["robot_0"] == 1.0 and info["new_interest"] == 1
    assert info["ready"] and info["target"] == 1
    assert abs(info["position"][0] - 5.0) <= 0.5  # within the arrival radius
    assert 2.5 <= info["time"] <= 5.0  # 5 m at <= 2 m/s, plus accelerating and braking
    # 400 s hold 131 nominal moves of 5 / 2 + 2 / 3.5705 = 3.06 s; this one took less
    assert info["time"] < 3.06 and env.state()["steps_left"] == 131
    assert env.state_space.contains(env.state())
    assert env.snapped.tolist() == [1]
    _, rewards, *_ = env.step({"robot_0": 0})  # stay: ready again after one period
    assert rewards["robot_0"] == 0.0 and math.isclose(env.time, info["time"] + 0.1)


def test_rate_mode_snaps_to_the_nearest_waypoint(path_graph) -> None:
    env = line_env(path_graph, retarget="rate")
    env.reset(seed=0, options={"robot_nodes": [0], "interest_nodes": [3]})
    for _ in range(40):
        env.step({"robot_0": 1})  # keep heading east from wherever it is snapped
        x = env.positions[0, 0]
        assert env.snapped[0] == int(np.floor(x / 5.0 + 0.5))
        assert env.snapshot().visited[env.snapped[0]]  # its own waypoint is visited
    assert 4.0 < env.positions[0, 0] < 9.0  # 4 s at up to 2 m/s, smoothly past waypoint 1


def test_only_ready_robots_take_new_targets(path_graph) -> None:
    env = line_env(path_graph, num_robots=2)
    env.reset(seed=0, options={"robot_nodes": [0, 7], "interest_nodes": [3]})
    env.step({"robot_0": 1, "robot_1": 0})  # robot_1 stays: ready after one period
    assert env.targets.tolist() == [1, 7] and env.ready.tolist() == [False, True]
    _, _, _, _, infos = env.step({"robot_0": 3, "robot_1": 3})  # robot_0 is not ready
    assert env.targets.tolist() == [1, 6]
    assert infos["robot_0"]["target"] == 1


@pytest.mark.parametrize("observe", ["snapped", "targets"])
def test_observations_place_robots_on_their_way_by_the_observe_rule(path_graph, observe) -> None:
    env = line_env(path_graph, num_robots=2, observe=observe)
    env.reset(seed=0, options={"robot_nodes": [0, 7], "interest_nodes": [1, 3]})
    obs, *_ = env.step({"robot_0": 1, "robot_1": 0})  # robot_1 stays: ready after one period
    assert env.ready.tolist() == [False, True] and env.snapped.tolist() == [0, 7]
    on_its_way = {"snapped": 0, "targets": 1}[observe]  # robot_0 has just left waypoint 0
    assert env.observed_nodes.tolist() == [on_its_way, 7]
    state = env.state()
    assert state["node_pos"][state["robot_nodes"]].tolist() == [[on_its_way, 0.0], [7.0, 0.0]]
    # Waypoint 1, robot_0's target, counts as visited in the targets view only; the
    # environment's own record (and the reward) is the same in both.
    shown = {"snapped": 2.0, "targets": 1.0}[observe]
    assert state["nodes"][:, 2].sum() == shown and obs["robot_1"]["nodes"][:, 2].sum() == shown
    assert not env.snapshot().visited[1]
    # Once robot_0 arrives it is ready, at its snapped waypoint, in both views.
    while not env.ready[0]:
        env.step({"robot_0": 0, "robot_1": 0})
    assert env.observed_nodes.tolist() == [1, 7] and env.snapshot().visited[1]


def test_bad_observe_rule_is_named() -> None:
    with pytest.raises(ValueError, match="observe must be one of"):
        DynamicsConfig(observe="future")


def test_targets_go_through_the_collision_resolver(path_graph) -> None:
    env = line_env(path_graph, num_robots=2)
    env.reset(seed=0, options={"robot_nodes": [2, 4], "interest_nodes": [3]})
    _, _, _, _, infos = env.step({"robot_0": 1, "robot_1": 3})  # both want waypoint 3
    assert env.targets.tolist() == [3, 4]  # the lower index wins, the other keeps its own
    assert infos["robot_1"]["blocked"] and not infos["robot_0"]["blocked"]


@pytest.mark.parametrize("backend", ["numpy", "auto"])
@pytest.mark.parametrize("altitudes, expected", [((5.0, 5.0), 1), ((3.0, 8.0), 0)])
def test_near_misses_count_crossings_at_one_altitude(
    path_graph, altitudes, expected, backend
) -> None:
    env = line_env(path_graph, num_robots=2, altitude_range=altitudes, backend=backend)
    env.reset(seed=0, options={"robot_nodes": [3, 4], "interest_nodes": [0]})
    env.step({"robot_0": 1, "robot_1": 3})  # they swap along one edge
    while not env.ready.all():
        env.step({"robot_0": 0, "robot_1": 0})
    assert env.targets.tolist() == [4, 3]
    assert env.near_misses == expected


def test_compiled_backend_flies_the_same_episode_as_numpy() -> None:
    pytest.importorskip("numba")
    config = {"map": "city", "num_robots": 10, "city_size": 40, "hops": 4}  # crowded
    dynamics = {"altitude_range": (5.0, 5.0), "noise_std": 0.05, "delay": 0.1, "max_time": 30.0}
    envs = [
        QuadrotorCoverageEnv(dynamics={**dynamics, "backend": b}, **config)
        for b in ("numpy", "numba")
    ]
    observations = [env.reset(seed=5)[0] for env in envs][0]
    rng = np.random.default_rng(0)
    while envs[0].agents:
        actions = {
            a: int(rng.choice(np.flatnonzero(o["action_mask"]))) for a, o in observations.items()
        }
        steps = [env.step(actions) for env in envs]
        assert steps[0][1] == steps[1][1]  # rewards
        observations = steps[0][0]
        reference, compiled = envs
        assert np.array_equal(reference.positions, compiled.positions)
        assert np.array_equal(reference.snapped, compiled.snapped)
        assert reference.near_misses == compiled.near_misses and reference.time == compiled.time
    assert envs[0].near_misses > 0  # one altitude, random moves: the count was exercised


@pytest.mark.parametrize("retarget", ["arrival", "rate"])
def test_infinite_speed_and_acceleration_reproduce_the_discrete_env(retarget: str) -> None:
    config = {"map": "city", "num_robots": 4, "city_size": 120, "hops": 5}
    for seed in range(3):
        discrete = marl_cover.parallel_env(max_steps=25, **config)
        dynamics = DynamicsConfig(
            quadrotor=QuadrotorParams.ideal(), retarget=retarget, max_time=2.5
        )
        continuous = QuadrotorCoverageEnv(dynamics=dynamics, **config)
        obs_d, _ = discrete.reset(seed=seed)
        obs_c, _ = continuous.reset(seed=seed)
        rng = np.random.default_rng(seed)
        steps = 0
        while discrete.agents:
            actions = {a: int(rng.choice(np.flatnonzero(obs_d[a]["action_mask"]))) for a in obs_d}
            obs_d, rew_d, term_d, trunc_d, info_d = discrete.step(actions)
            obs_c, rew_c, term_c, trunc_c, info_c = continuous.step(actions)
            steps += 1
            for agent in obs_d:
                for key in obs_d[agent]:
                    assert np.array_equal(obs_d[agent][key], obs_c[agent][key]), (steps, key)
                assert info_d[agent]["new_interest"] == info_c[agent]["new_interest"]
                assert info_d[agent]["blocked"] == info_c[agent]["blocked"]
            assert (rew_d, term_d, trunc_d) == (rew_c, term_c, trunc_c)
            state_d, state_c = discrete.state(), continuous.state()
            assert np.array_equal(state_d["nodes"], state_c["nodes"])
            assert state_d["steps_left"] == state_c["steps_left"] == 25 - steps
            assert continuous.state_space.contains(state_c)
        assert not continuous.agents and steps == 25
        assert math.isclose(continuous.time, 2.5)


def small_quadrotor_env(**dynamics) -> QuadrotorCoverageEnv:
    return marl_cover.quadrotor_parallel_env(
        map="city",
        num_robots=3,
        city_size=80,
        hops=4,
        dynamics={"max_time": 20.0, **dynamics},
    )


@pytest.mark.filterwarnings("ignore:reset ignores unknown option")
def test_pettingzoo_api_and_seeding() -> None:
    parallel_api_test(small_quadrotor_env(), num_cycles=200)
    parallel_seed_test(lambda: small_quadrotor_env(noise_std=0.2, delay=0.1))


def test_reset_warns_about_unknown_options_at_the_callers_line() -> None:
    for env in (small_quadrotor_env(), marl_cover.parallel_env(map="city", city_size=80)):
        with pytest.warns(UserWarning, match="reset ignores unknown option 'bogus'") as record:
            obs, _ = env.reset(seed=0, options={"bogus": 1})
        assert [Path(w.filename).name for w in record] == [Path(__file__).name]
        assert sorted(obs) == env.possible_agents


def test_same_seed_and_actions_give_the_same_flight_bit_for_bit() -> None:
    runs = []
    for _ in range(2):
        env = small_quadrotor_env(noise_std=0.3)
        obs, _ = env.reset(seed=5)
        rng = np.random.default_rng(1)
        trace = []
        while env.agents:
            actions = {a: int(rng.choice(np.flatnonzero(obs[a]["action_mask"]))) for a in obs}
            obs, rewards, _, _, infos = env.step(actions)
            trace.append((env.time, env.positions.tobytes(), rewards["robot_0"]))
        runs.append(trace)
    assert runs[0] == runs[1] and len(runs[0]) > 5


def test_registered_id_makes_the_quadrotor_env() -> None:
    import pettingzoo

    env = pettingzoo.make("parallel", "marl_cover/CoverageQuadrotor-v0", map="city", city_size=60)
    assert isinstance(env, QuadrotorCoverageEnv)


def test_render_draws_robots_between_waypoints(path_graph) -> None:
    env = QuadrotorCoverageEnv(graph=path_graph, num_robots=1, render_mode="rgb_array")
    env.reset(seed=0, options={"robot_nodes": [0], "interest_nodes": [3]})
    at_start = env.render()
    env.step({"robot_0": 1})
    moved = env.render()
    env.close()
    assert at_start.shape == moved.shape and at_start.dtype == np.uint8
    assert not np.array_equal(at_start, moved)


def test_a_quadrotor_fork_flies_the_same_future_alone() -> None:
    """``fork()`` mid-mission shares the dynamics, the kernels and the waypoint lookup, and
    copies the bodies: the fork and then the original fly the same 20 steps, bit for bit."""
    env = QuadrotorCoverageEnv(num_robots=3, hops=5, city_size=150)
    env.reset(seed=1)
    for _ in range(5):
        env.step({agent: 1 for agent in env.agents})  # east
    fork = env.fork()
    assert fork.dynamics is env.dynamics and fork.snapshot().graph is env.snapshot().graph
    moves = [{agent: (i % 4) + 1 for agent in fork.agents} for i in range(20)]
    ahead = [fork.step(m)[1] for m in moves]
    assert fork.time > env.time
    assert [env.step(m)[1] for m in moves] == ahead
    np.testing.assert_array_equal(env.positions, fork.positions)
