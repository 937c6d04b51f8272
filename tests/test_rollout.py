"""One-step rollout improvement: exact play-outs, labels on tiny graphs, never worse than its
base, and the labelled shards of ``scripts/collect_rollout_labels.py``."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import run_script

import marl_cover
from agents.datasets import load_dataset
from agents.evaluation import evaluate
from agents.rollout import GNNArgmax, RolloutPolicy, fork, play_out

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
    reaches 5 and 6 (2 points): the values of ``counterfactual_returns``."""
    pytest.importorskip("numba")
    from agents.greedy import counterfactual_returns

    env = path_env(path_graph, [3], [1, 5, 6], max_steps=3)
    assert RolloutPolicy(Constant(WEST)).improve(env).tolist() == [WEST]
    finish = RolloutPolicy(Constant(WEST), sequential=False, greedy_after=1)
    assert finish.improve(env).tolist() == [EAST]
    assert finish.accept.tolist() == [1 << EAST]
    assert counterfactual_returns(env, 7, np.array([WEST])).tolist() == [[1, 2, 1, 1, 1]]
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
    from agents.models import AggregationGNN, GNNConfig
    from agents.models.policy import GNNPolicy

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
    from agents.models import AggregationGNN, GNNConfig
    from agents.models.policy import save_model

    torch.manual_seed(2)
    path = tmp_path / "m.pt"
    save_model(path, AggregationGNN(GNNConfig(kind="nonlinear", hops=3)), {"note": "random"})
    return path


def test_collected_shards_label_the_learners_own_states(tmp_path, random_model_file) -> None:
    out = tmp_path / "labels"
    args = [
        f"checkpoint={random_model_file}",
        "task=exploration",
        "episodes=3",
        "shard_size=2",
        "seed=50",
        "env.map=city",
        "env.city_size=60",
        "env.num_robots=3",
        "env.max_steps=6",
        f"out={out}",
        "progress=false",
    ]
    result = run_script("collect_rollout_labels.py", *args)
    assert result.returncode == 0, result.stderr
    summary = json.loads((out / "summary.json").read_text())
    episodes = load_dataset(out)
    assert [e.seed for e in episodes] == [50, 51, 52]
    assert summary["episodes"] == 3 and summary["decisions"] == 3 * 6 * 3
    # the trajectory is the learner's argmax; a label leaves it only for a better move
    from agents.models.policy import load_model

    base = GNNArgmax(load_model(random_model_file)[0])
    env = marl_cover.parallel_env(
        task="exploration", map="city", city_size=60, num_robots=3, max_steps=6, hops=3
    )
    changed = stays = 0
    for episode in episodes:
        env.reset(seed=episode.seed)
        for step in range(episode.num_steps):
            np.testing.assert_array_equal(env.snapshot().robot_node, episode.robot_node[step])
            own = base([env.state()])[0]
            label, accept = episode.actions[step], episode.accept[step].astype(np.int64)
            assert ((accept >> label) & 1).all()  # the label is among the accepted moves
            assert (((accept >> own) & 1) == (label == own)).all()  # own move: kept iff best
            changed += int((label != own).sum())
            stays += int(((label != own) & (label == 0)).sum())
            env.apply_actions(own)
    assert changed == summary["changed"] > 0
    assert stays == summary["changed_to_stay"]
    # the same command finishes nothing twice; another seed in that folder is refused
    stamp = (out / "shard_00000.npz").stat().st_mtime_ns
    # (a shard of an older run, without the stays: their total is unknown, not zero)
    rows = json.loads((out / "shard_00000.json").read_text())
    old = [{k: v for k, v in row.items() if k != "changed_to_stay"} for row in rows]
    (out / "shard_00000.json").write_text(json.dumps(old))
    assert run_script("collect_rollout_labels.py", *args).returncode == 0
    assert (out / "shard_00000.npz").stat().st_mtime_ns == stamp
    again = json.loads((out / "summary.json").read_text())
    assert again["changed"] == summary["changed"] and again["changed_to_stay"] is None
    refused = run_script("collect_rollout_labels.py", *args[:-2], "seed=7", f"out={out}")
    assert refused.returncode != 0 and "seed" in refused.stderr


def test_cli_plays_the_rollout_policy(tmp_path, random_model_file) -> None:
    rewards = {}
    for policy in ("gnn", "gnn_rollout"):
        out = tmp_path / f"{policy}.json"
        result = run_script(
            "evaluate.py",
            f"policy={policy}",
            f"checkpoint={random_model_file}",
            "episodes=3",
            "num_robots=3",
            "max_steps=8",
            "city_size=80",
            f"out={out}",
        )
        assert result.returncode == 0, result.stderr
        rewards[policy] = [r["reward"] for r in json.loads(out.read_text())["summary"]["results"]]
    assert all(r >= g for r, g in zip(rewards["gnn_rollout"], rewards["gnn"], strict=True))
    out = tmp_path / "finish.json"
    finish = ("policy=gnn_rollout", "gnn.greedy_after=1", "gnn.sequential=false", f"out={out}")
    common = (f"checkpoint={random_model_file}", "episodes=3", "num_robots=3", "max_steps=8")
    result = run_script("evaluate.py", *finish, *common, "city_size=80")
    assert result.returncode == 0, result.stderr
    record = json.loads(out.read_text())
    assert record["gnn"]["greedy_after"] == 1
    assert record["summary"]["policy_counts"]["play_outs"] > 0
    refused = run_script("evaluate.py", "policy=gnn_rollout", "checkpoint=a.pt,b.pt")
    assert refused.returncode != 0 and "not an ensemble" in refused.stderr


def test_beta_one_records_the_rollout_policys_own_episode() -> None:
    from agents.models import AggregationGNN, GNNConfig
    from agents.rollout_labels import RolloutLabelConfig, record_rollout_episode

    torch.manual_seed(3)
    base = GNNArgmax(AggregationGNN(GNNConfig(kind="nonlinear", hops=3)).double())
    env = marl_cover.parallel_env(num_robots=3, hops=3, max_steps=8)
    episode, counts = record_rollout_episode(env, base, RolloutPolicy(base), seed=5, beta=1.0)
    played = evaluate(env, RolloutPolicy(base), [5]).results[0].reward
    assert counts["total"] == played == episode.reward()
    learner_only, _ = record_rollout_episode(env, base, RolloutPolicy(base), seed=5)
    assert counts["total"] >= learner_only.reward()
    with pytest.raises(ValueError, match="beta must be in"):
        RolloutLabelConfig(beta=1.5)


def test_own_labels_are_the_learners_moves() -> None:
    from agents.models import AggregationGNN, GNNConfig
    from agents.rollout_labels import RolloutLabelConfig, record_rollout_episode

    torch.manual_seed(4)
    base = GNNArgmax(AggregationGNN(GNNConfig(kind="nonlinear", hops=3)).double())
    env = marl_cover.parallel_env(num_robots=3, hops=3, max_steps=6)
    episode, counts = record_rollout_episode(env, base, None, seed=2)
    labelled, _ = record_rollout_episode(env, base, RolloutPolicy(base), seed=2)
    np.testing.assert_array_equal(episode.robot_node, labelled.robot_node)  # the same states
    env.reset(seed=2)
    for step in range(episode.num_steps):
        own = base([env.state()])[0]
        np.testing.assert_array_equal(episode.actions[step], own)
        np.testing.assert_array_equal(episode.accept[step], 1 << own)
        env.apply_actions(own)
    assert counts["changed"] == 0
    with pytest.raises(ValueError, match="labels must be 'rollout', 'own' or 'local'"):
        RolloutLabelConfig(labels="expert")
    with pytest.raises(ValueError, match="margin must be >= 0, got -1"):
        RolloutLabelConfig(labels="local", margin=-1.0)
    with pytest.raises(FileNotFoundError, match=r"no model file at nowhere.pt \(checkpoint\)"):
        RolloutLabelConfig(checkpoint="nowhere.pt")
    for options in ({"greedy_after": 0}, {"labels": "own", "greedy_after": 1}):
        with pytest.raises(ValueError, match="greedy_after must be >= 1 with labels='rollout'"):
            RolloutLabelConfig(**options)
    with pytest.raises(ValueError, match="plays coverage only, not task='exploration'"):
        RolloutLabelConfig(task="exploration", greedy_after=1)
    assert RolloutLabelConfig(labels="local", greedy_after=0).greedy_after == 0


def test_labels_that_stay_where_the_learner_moves_are_counted() -> None:
    from agents.models import AggregationGNN, GNNConfig
    from agents.rollout_labels import record_rollout_episode

    class FirstRobotStays:
        """A labeller: robot 0 stays, the others keep the learner's moves."""

        def __init__(self, learner: GNNArgmax) -> None:
            self.learner, self.accept = learner, np.zeros(0, dtype=np.int64)

        def improve(self, env) -> np.ndarray:  # noqa: ANN001
            label = self.learner([env.state()])[0].copy()
            label[0] = 0
            self.accept = (1 << label).astype(np.int64)
            return label

    torch.manual_seed(4)
    base = GNNArgmax(AggregationGNN(GNNConfig(kind="nonlinear", hops=3)).double())
    env = marl_cover.parallel_env(num_robots=3, hops=3, max_steps=6)
    own, _ = record_rollout_episode(env, base, None, seed=2)
    episode, counts = record_rollout_episode(env, base, FirstRobotStays(base), seed=2)
    np.testing.assert_array_equal(episode.robot_node, own.robot_node)  # the learner's states
    moved = int((own.actions[:, 0] != 0).sum())  # the steps where robot 0 moves
    assert 0 < moved == counts["changed"] == counts["changed_to_stay"]
    assert (episode.actions[:, 0] == 0).all()


def test_play_outs_cut_short_and_finished_by_another_policy(path_graph) -> None:
    """Robot on 3 of the 8-waypoint path, points on 1, 5 and 6, five steps. East then the
    "west" base for two steps collects nothing; finished by greedy from there (robot on 3,
    three steps left) it collects 5 and 6; to the end on "west" it collects 1."""
    from agents.greedy import greedy_return

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
