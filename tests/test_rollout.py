"""One-step rollout improvement: exact play-outs, labels on tiny graphs, never worse than its
base, and the rollout policy from the command line."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import run_cli

import marl_cover
from marl_cover.agents.evaluation.episodes import evaluate
from marl_cover.agents.planners.rollout import GNNArgmax, RolloutPolicy, fork, play_out

torch = pytest.importorskip("torch")
torch.set_num_threads(1)

STAY, EAST, WEST = 0, 1, 3


class Constant:
    """A base policy that asks every robot for one action (a stay where it is masked)."""

    def __init__(self, action: int) -> None:
        self.action = action

    def __call__(self, states: list[dict[str, np.ndarray]]) -> np.ndarray:
        mask = np.stack([s["action_mask"] for s in states])  # (B, R, 5)
        return np.where(mask[..., self.action], self.action, STAY)


def path_env(path_graph, robots, interest, max_steps):
    env = marl_cover.parallel_env(
        graph=path_graph, num_robots=len(robots), hops=7, max_steps=max_steps
    )
    env.reset(seed=0, options={"robot_nodes": robots, "interest_nodes": interest})
    return env


def test_one_step_deviation_toward_a_point(path_graph) -> None:
    # robot on 3 of the path 0..7, a point at 4; the base stays, so only the first step counts
    env = path_env(path_graph, [3], [4], max_steps=3)
    rollout = RolloutPolicy(Constant(STAY))
    assert play_out(env, Constant(STAY), np.array([[STAY], [EAST], [WEST]])).tolist() == [0, 1, 0]
    assert rollout.improve(env).tolist() == [EAST]
    assert rollout.accept.tolist() == [1 << EAST]
    # points on both sides: both moves return 1, the lowest action wins, both are accepted
    env = path_env(path_graph, [3], [2, 4], max_steps=3)
    assert rollout.improve(env).tolist() == [EAST]
    assert rollout.accept.tolist() == [(1 << EAST) | (1 << WEST)]
    assert rollout.counts == {"play_outs": 6, "decisions": 2, "changed": 2}


def test_greedy_finish_after_the_joint_move(path_graph) -> None:
    """Robot on 3, points at 1, 5 and 6, three steps, a base that walks west. Played out by
    the base, west (1 point) beats east (0); finished by greedy after the first step, east
    reaches 5 and 6 (2 points): greedy's returns after each first move."""
    pytest.importorskip("numba")
    from marl_cover.agents.baselines.greedy import greedy_return

    env = path_env(path_graph, [3], [1, 5, 6], max_steps=3)
    assert RolloutPolicy(Constant(WEST)).improve(env).tolist() == [WEST]
    finish = RolloutPolicy(Constant(WEST), sequential=False, greedy_after=1)
    assert finish.improve(env).tolist() == [EAST]
    assert finish.accept.tolist() == [1 << EAST]
    assert [greedy_return(env, 7, np.array([move])) for move in range(5)] == [1, 2, 1, 1, 1]
    # two steps of the base first: west, west reaches 1; east then west reaches nothing
    assert RolloutPolicy(Constant(WEST), greedy_after=2).improve(env).tolist() == [WEST]
    with pytest.raises(ValueError, match="greedy_after must be >= 1 step"):
        RolloutPolicy(Constant(WEST), greedy_after=0)


def test_ties_keep_the_base_move(path_graph) -> None:
    # points far east; the base walks west and no single step changes what it collects
    env = path_env(path_graph, [3], [6, 7], max_steps=3)
    rollout = RolloutPolicy(Constant(WEST))
    assert rollout.improve(env).tolist() == [WEST]
    assert rollout.accept.tolist() == [(1 << STAY) | (1 << EAST) | (1 << WEST)]
    # with time to reach them, going east first and then west still collects nothing more
    env = path_env(path_graph, [3], [4], max_steps=3)
    assert rollout.improve(env).tolist() == [EAST]  # 3 -> 4 (a point) -> 3 -> 2


def test_robots_decide_in_turn_or_against_the_base(path_graph) -> None:
    # two robots at 2 and 5, one point at 3 and one at 4; the base stays
    env = path_env(path_graph, [2, 5], [3, 4], max_steps=2)
    sequential = RolloutPolicy(Constant(STAY))
    assert sequential.improve(env).tolist() == [EAST, WEST]
    assert sequential.accept.tolist() == [1 << EAST, 1 << WEST]
    against_base = RolloutPolicy(Constant(STAY), sequential=False)
    assert against_base.improve(env).tolist() == [EAST, WEST]
    # one point at 3, between them: each robot alone would take it, so both are sent; in
    # turn, the second robot sees the first take it and keeps its stay
    env = path_env(path_graph, [2, 4], [3], max_steps=2)
    assert against_base.improve(env).tolist() == [EAST, WEST]
    assert sequential.improve(env).tolist() == [EAST, STAY]
    assert sequential.accept.tolist() == [1 << EAST, (1 << STAY) | (1 << EAST) | (1 << WEST)]


def episode_return(env, policy, seed: int) -> float:
    return evaluate(env, policy, [seed]).results[0].reward


@pytest.mark.parametrize("task", ["coverage", "exploration"])
def test_rollout_is_never_worse_than_its_gnn_and_leaves_the_env_alone(task: str) -> None:
    from marl_cover.agents.models import AggregationGNN, GNNConfig
    from marl_cover.agents.models.policy import GNNPolicy

    torch.manual_seed(1)
    model = AggregationGNN(GNNConfig(kind="nonlinear", hops=3)).double()
    env = marl_cover.parallel_env(task=task, num_robots=3, hops=3, max_steps=8)
    base, rollout = GNNArgmax(model), RolloutPolicy(GNNArgmax(model))
    gnn = GNNPolicy(model, centralized=True)
    gains = []
    for seed in range(4):
        env.reset(seed=seed)
        first = 0.0
        for _ in range(3):
            first += float(env.apply_actions(base([env.state()])[0]).new_interest.sum())
        # the base's play-out from mid-episode is the rest of the base's own episode
        rest = play_out(env, base, base([env.state()]))[0]
        before = fork(env)
        rollout.improve(env)
        for key, value in before.state().items():
            np.testing.assert_array_equal(env.state()[key], value)
        played = episode_return(env, gnn, seed)
        assert first + rest == played
        gains.append(episode_return(env, rollout, seed) - played)
    assert min(gains) >= 0 and max(gains) > 0
    assert rollout.counts["changed"] > 0


@pytest.fixture
def random_model_file(tmp_path):
    from marl_cover.agents.models import AggregationGNN, GNNConfig
    from marl_cover.agents.models.checkpoints import save_model

    torch.manual_seed(2)
    path = tmp_path / "m.pt"
    save_model(path, AggregationGNN(GNNConfig(kind="nonlinear", hops=3)), {"note": "random"})
    return path


def test_cli_plays_the_rollout_policy(tmp_path, random_model_file) -> None:
    rewards = {}
    for policy in ("gnn", "gnn_rollout"):
        out = tmp_path / f"{policy}.json"
        result = run_cli(
            "evaluate",
            f"policy={policy}",
            f"model={random_model_file}",
            "episodes=3",
            "env.num_robots=3",
            "env.max_steps=8",
            "env.city_size=80",
            f"out={out}",
        )
        assert result.returncode == 0, result.stderr
        rewards[policy] = [r["reward"] for r in json.loads(out.read_text())["summary"]["results"]]
    assert all(r >= g for r, g in zip(rewards["gnn_rollout"], rewards["gnn"], strict=True))
    out = tmp_path / "finish.json"
    finish = ("policy=gnn_rollout", "gnn.greedy_after=1", "gnn.sequential=false", f"out={out}")
    common = (f"model={random_model_file}", "episodes=3", "env.num_robots=3", "env.max_steps=8")
    result = run_cli("evaluate", *finish, *common, "env.city_size=80")
    assert result.returncode == 0, result.stderr
    record = json.loads(out.read_text())
    assert record["config"]["gnn"]["greedy_after"] == 1
    assert record["summary"]["policy_counts"]["play_outs"] > 0
    refused = run_cli("evaluate", "policy=gnn_rollout", "model=a.pt")
    assert refused.returncode != 0 and "no model file at a.pt" in refused.stderr


def test_play_outs_cut_short_and_finished_by_another_policy(path_graph) -> None:
    """Robot on 3 of the 8-waypoint path, points on 1, 5 and 6, five steps. East then the
    "west" base for two steps collects nothing; finished by greedy from there (robot on 3,
    three steps left) it collects 5 and 6; to the end on "west" it collects 1."""
    from marl_cover.agents.baselines.greedy import greedy_return

    env = path_env(path_graph, [3], [1, 5, 6], max_steps=5)
    joints = np.array([[EAST]])
    assert play_out(env, Constant(WEST), joints).tolist() == [1.0]
    finished = play_out(
        env, Constant(WEST), joints, steps=2, finish=lambda rest: greedy_return(rest, 7)
    )
    assert finished.tolist() == [2.0]
    assert play_out(env, Constant(WEST), joints, steps=2).tolist() == [0.0]
    with pytest.raises(ValueError, match="at least the joint action's step, got steps=0"):
        play_out(env, Constant(WEST), joints, steps=0)
