"""Routing experts: exact optima on tiny graphs, fallbacks, re-planning after a block."""

from __future__ import annotations

import pytest

import marl_cover
from marl_cover.agents.evaluation.episodes import evaluate
from marl_cover.agents.experts import LocalRoutingExpert, RoutingExpert, build_problem, solve

pytest.importorskip("pyvrp")
pytest.importorskip("ortools")

BACKENDS = ["pyvrp", "ortools"]


def path_env(path_graph, robots, interest, max_steps):
    env = marl_cover.parallel_env(
        graph=path_graph, num_robots=len(robots), hops=7, max_steps=max_steps
    )
    env.reset(seed=0, options={"robot_nodes": robots, "interest_nodes": interest})
    return env


def play(env, expert) -> float:
    """The team reward of one episode played by ``expert``."""
    total = 0.0
    while env.agents:
        _, rewards, *_ = env.step(expert.act_env(env))
        total += rewards["robot_0"]
    return total


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(("max_steps", "optimum"), [(4, 2), (8, 3), (9, 3), (10, 4)])
def test_single_robot_optimum(path_graph, backend, max_steps, optimum) -> None:
    # robot on 3 of the path 0..7, points at 0, 1, 6, 7
    env = path_env(path_graph, [3], [0, 1, 6, 7], max_steps)
    problem = build_problem(env.snapshot())
    assert problem.candidates.tolist() == [0, 1, 6, 7][: 4 if max_steps >= 4 else 0]
    routes = solve(problem, backend, time_limit=0.2)
    assert problem.is_feasible(routes)
    assert sum(map(len, routes)) == optimum


@pytest.mark.parametrize("backend", BACKENDS)
def test_two_robots_split_the_work(tee_graph, backend) -> None:
    env = marl_cover.parallel_env(graph=tee_graph, num_robots=2, hops=5, max_steps=2)
    env.reset(seed=0, options={"robot_nodes": [1, 2], "interest_nodes": [0, 3, 4, 5]})
    problem = build_problem(env.snapshot())
    routes = solve(problem, backend, time_limit=0.2)
    # robot_0 on 1 takes 4 then 5 (or 0); robot_1 on 2 takes 3: three points in two steps
    assert problem.is_feasible(routes) and sum(map(len, routes)) == 3


@pytest.mark.parametrize("backend", BACKENDS)
def test_expert_collects_the_optimum_in_the_env(path_graph, backend) -> None:
    env = path_env(path_graph, [3], [0, 1, 6, 7], 10)
    expert = RoutingExpert(backend=backend, time_limit=0.2)
    assert play(env, expert) == 4
    assert expert.counts["solves"] == 1 and expert.counts["failed_solve"] == 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_stranded_robot_falls_back_to_greedy(path_graph, backend) -> None:
    # receding horizon 2: point 7 is four hops from robot 3, out of the plan's reach
    env = path_env(path_graph, [3], [7], 10)
    expert = RoutingExpert(backend=backend, mode="receding", horizon=2, time_limit=0.1)
    assert expert.act_env(env) == {"robot_0": 1}  # the fallback sees the whole map: east
    assert expert.info == {"fallback": 1, "replanned": True}
    short = RoutingExpert(
        backend=backend, mode="receding", horizon=2, time_limit=0.1, fallback_reach=2
    )
    assert short.act_env(env) == {"robot_0": 0}  # nothing within two hops: stay
    open_loop = RoutingExpert(backend=backend, time_limit=0.1)
    env = path_env(path_graph, [3], [7], 3)  # three steps left: unreachable in open loop
    assert open_loop.act_env(env) == {"robot_0": 1}  # greedy heads east anyway
    assert open_loop.counts["fallback_steps"] == 1


@pytest.mark.parametrize("backend", BACKENDS)
def test_zero_time_limit_never_crashes(backend) -> None:
    env = marl_cover.parallel_env(num_robots=4, hops=19, max_steps=10)
    expert = RoutingExpert(backend=backend, time_limit=0.0)
    summary = evaluate(env, expert, range(2))
    assert summary.episodes == 2 and summary.mean > 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_open_loop_replans_after_a_block(path_graph, backend) -> None:
    env = path_env(path_graph, [3, 4], [0, 1, 6, 7], 10)
    expert = RoutingExpert(backend=backend, time_limit=0.1)
    planned = expert.act_env(env)
    assert planned == {"robot_0": 3, "robot_1": 1}  # west and east
    env.step({"robot_0": 0, "robot_1": 0})  # the robots did not move as planned
    expert.act_env(env)
    assert expert.counts["replans"] == 1 and expert.counts["solves"] == 2
    env.step({"robot_0": 3, "robot_1": 1})  # as planned: the plan is kept
    expert.act_env(env)
    assert expert.counts["replans"] == 1 and expert.counts["solves"] == 2


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="backend"):
        RoutingExpert(backend="gurobi")
    with pytest.raises(ValueError, match="horizon"):
        RoutingExpert(mode="receding")


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("warm_start", [True, False])
def test_receding_horizon_reaches_the_optimum(path_graph, backend, warm_start) -> None:
    env = path_env(path_graph, [3], [0, 1, 6, 7], 10)
    expert = RoutingExpert(
        backend=backend, mode="receding", horizon=10, time_limit=0.05, warm_start=warm_start
    )
    assert play(env, expert) == 4
    assert expert.counts["solves"] == 10 and expert.counts["failed_solve"] == 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_local_expert_plans_on_what_each_robot_sees(path_graph, backend) -> None:
    """Robots on 3 and 7, points on 0, 5 and 6, horizon 3. The team expert sends robot_0 west
    to 0 and leaves 5 and 6 to robot_1; robot_0 alone does not see robot_1 (four hops away)
    and heads east for the two points it sees, while robot_1 sees only 5 and 6 as well."""
    env = path_env(path_graph, [3, 7], [0, 5, 6], 10)
    team = RoutingExpert(backend=backend, mode="receding", horizon=3, time_limit=0.1)
    assert team.act_env(env) == {"robot_0": 3, "robot_1": 3}  # west, west
    local = LocalRoutingExpert(3, backend=backend, time_limit=0.1)
    view = local.view(env.snapshot(), 0)
    assert view.robot_node.tolist() == [3] and view.discovered.nonzero()[0].tolist() == [
        0,
        1,
        2,
        3,
        4,
        5,
        6,
    ]
    assert local.view(env.snapshot(), 1).robot_node.tolist() == [7]
    assert local.act_env(env) == {"robot_0": 1, "robot_1": 3}  # east, west
    assert local.counts["solves"] == 2 and local.counts["fallback_steps"] == 0


def test_local_expert_falls_back_when_nothing_is_in_view(path_graph) -> None:
    env = path_env(path_graph, [3], [7], 10)  # four hops away, beyond a horizon of 3
    stay = LocalRoutingExpert(3, max_iterations=10)
    assert stay.act_env(env) == {"robot_0": 0} and stay.counts["fallback_steps"] == 1
    moves = set()
    for seed in range(8):
        wander = LocalRoutingExpert(3, max_iterations=10, fallback="random")
        wander.reset(seed)
        first = wander.act_env(env)["robot_0"]
        wander.reset(seed)
        assert wander.act_env(env)["robot_0"] == first  # the seed decides
        moves.add(first)
    assert moves == {1, 3}  # east or west, never stay
    assert LocalRoutingExpert(4, max_iterations=10).act_env(env) == {"robot_0": 1}
    with pytest.raises(ValueError, match="fallback must be one of"):
        LocalRoutingExpert(3, fallback="spin")
