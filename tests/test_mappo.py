"""MAPPO: actor and critic modules, the batch preparation, learning on a tiny task, the script."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("torchrl")

from helpers import run_script  # noqa: E402

from agents import configuration  # noqa: E402
from agents.batched_env import BatchedCoverageEnv  # noqa: E402
from agents.evaluation import evaluate  # noqa: E402
from agents.models.gnn import AggregationGNN, GNNConfig  # noqa: E402
from agents.models.policy import (  # noqa: E402
    EgoGraphLogits,
    GNNPolicy,
    StateLogits,
    load_model,
    save_model,
)
from agents.models.value import EgoValue, StateValue  # noqa: E402
from agents.training.mappo import (  # noqa: E402
    ALL_ADVANTAGES_KEY,
    ANCHOR_KEY,
    COUNTERFACTUAL_KEY,
    OLD_LOGITS_KEY,
    MAPPOConfig,
    all_action_objective,
    anchor_kl,
    anchor_log_probs,
    build_actor,
    build_critic,
    build_loss,
    counterfactual_advantages,
    episode_rewards,
    prepare_batch,
    train_mappo,
)
from marl_cover.env import CoverageEnv  # noqa: E402
from marl_cover.maps import paper_map_path  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
TINY_ENV = {"map": "city", "city_size": 60, "num_robots": 3, "max_steps": 10, "hops": 3}
GRAPH_IN = ("nodes", "edge_index", "edge_attr", "edge_mask", "node_mask")


def tiny_config(tmp_path: Path, *overrides: str) -> MAPPOConfig:
    base = [
        f"out={tmp_path / 'run'}",
        "model.actor.hops=3",
        "model.critic.hops=3",
        "collector.frames_per_batch=400",
        "optim.minibatch_size=100",
        "eval.every=5",
        "eval.episodes=5",
        "logger=none",
        "progress=false",
    ]
    values = configuration.as_dict(MAPPOConfig())
    values["env"] = dict(TINY_ENV)
    return configuration.build(
        MAPPOConfig, configuration.apply_overrides(values, base + list(overrides))
    )


@pytest.fixture(scope="module")
def rollout() -> object:
    """Twelve steps of 2 tiny episodes under random actions (ego-graphs and states)."""
    env = BatchedCoverageEnv(2, **TINY_ENV)
    env.set_seed(5)
    torch.manual_seed(0)
    return env.rollout(12, break_when_any_done=False)


@pytest.mark.parametrize("kind", ["linear", "nonlinear"])
def test_state_actor_equals_ego_actor(rollout, kind: str) -> None:  # noqa: ANN001
    torch.manual_seed(1)
    gnn = AggregationGNN(GNNConfig(kind=kind, hops=3)).double()
    state = {k: rollout["state", k] for k in GRAPH_IN}
    obs = {k: rollout["robot", "observation", k] for k in GRAPH_IN}
    mask = rollout["robot", "action_mask"]
    state = {k: v.double() if v.is_floating_point() else v for k, v in state.items()}
    obs = {k: v.double() if v.is_floating_point() else v for k, v in obs.items()}
    central, central_mask = StateLogits(gnn, 3)(*state.values(), mask)  # (2, 12, 3, 5)
    ego, ego_mask = EgoGraphLogits(gnn)(*list(obs.values())[:4], mask)
    assert central.shape == (2, 12, 3, 5)
    assert torch.equal(central_mask, ego_mask)
    assert torch.equal(central_mask, mask)
    torch.testing.assert_close(central, ego, rtol=0, atol=1e-10)


def test_critics_read_the_stay_edge(rollout) -> None:  # noqa: ANN001
    torch.manual_seed(2)
    gnn = AggregationGNN(GNNConfig(kind="nonlinear", hops=3)).double()
    state = [rollout["state", k] for k in GRAPH_IN]
    state = [v.double() if v.is_floating_point() else v for v in state]
    obs = [rollout["robot", "observation", k] for k in GRAPH_IN]
    obs = [v.double() if v.is_floating_point() else v for v in obs]
    per_robot = StateValue(gnn, 3)(*state)  # (2, 12, 3, 1)
    assert per_robot.shape == (2, 12, 3, 1)
    torch.testing.assert_close(per_robot, EgoValue(gnn)(*obs), rtol=0, atol=1e-10)
    team = StateValue(gnn, 3, aggregate="sum")(*state)
    torch.testing.assert_close(team, per_robot.sum(-2, keepdim=True).expand(-1, -1, 3, 1))
    with pytest.raises(ValueError, match="aggregate"):
        StateValue(gnn, 3, aggregate="max")


def test_time_aware_critics_read_steps_left(rollout) -> None:  # noqa: ANN001
    # a 10-step episode: the state's steps_left counts down and restarts after the reset
    steps_left = rollout["state", "steps_left"]  # (2, 12)
    assert steps_left[0].tolist() == [10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 10, 9]
    assert rollout["next", "state", "steps_left"][0, 9] == 0  # the last step's next state
    torch.manual_seed(4)
    gnn = AggregationGNN(GNNConfig(kind="nonlinear", hops=3, node_features=5)).double()
    state = [rollout["state", k] for k in GRAPH_IN]
    state = [v.double() if v.is_floating_point() else v for v in state]
    values = StateValue(gnn, 3, horizon=10)(*state, steps_left)  # (2, 12, 3, 1)
    # the same as the network on the nodes with steps_left / 10 appended to every node
    nodes = state[0]
    column = (steps_left.double() / 10)[..., None, None].expand(*nodes.shape[:-1], 1)
    expected = StateValue(gnn, 3)(torch.cat([nodes, column], -1), *state[1:])
    torch.testing.assert_close(values, expected, rtol=0, atol=0)
    # the same graphs with one step left are valued otherwise
    later = StateValue(gnn, 3, horizon=10)(*state, torch.ones_like(steps_left))
    assert not torch.allclose(values, later)
    # the ego critic reads the same feature (steps_left broadcast over the robots)
    obs = [rollout["robot", "observation", k] for k in GRAPH_IN]
    obs = [v.double() if v.is_floating_point() else v for v in obs]
    torch.testing.assert_close(
        EgoValue(gnn, horizon=10)(*obs, steps_left), values, atol=1e-10, rtol=0
    )
    with pytest.raises(ValueError, match="steps_left"):
        StateValue(gnn, 3, horizon=10)(*state)
    with pytest.raises(ValueError, match="horizon"):
        StateValue(gnn, 3, horizon=0)


def test_end_is_terminal_makes_truncation_terminal(rollout) -> None:  # noqa: ANN001
    truncated = rollout["next", "truncated"]
    assert truncated.any() and not rollout["next", "terminated"].any()
    plain = prepare_batch(rollout.copy(), 1.0)
    assert not plain["next", "robot", "terminated"].any()
    finite = prepare_batch(rollout.copy(), 1.0, end_is_terminal=True)
    assert torch.equal(finite["next", "robot", "terminated"][..., 0, :], truncated)
    assert torch.equal(finite["next", "robot", "done"], plain["next", "robot", "done"])


def test_prepare_batch_and_episode_rewards(rollout) -> None:  # noqa: ANN001
    data = rollout.copy()
    done = data["next", "done"]
    assert done.any()  # 12 steps cross the 10-step episode end
    prepared = prepare_batch(data, reward_scale=0.5)
    assert prepared["next", "robot", "done"].shape == (2, 12, 3, 1)
    assert torch.equal(prepared["next", "robot", "done"][..., 0, :], done)
    assert torch.equal(prepared["next", "robot", "reward"], rollout["next", "robot", "reward"] / 2)
    assert "done" not in rollout["next", "robot"].keys()  # noqa: SIM118 (the input is untouched)
    own = prepare_batch(rollout.copy(), reward_scale=1.0, reward="own")["next", "robot", "reward"]
    assert torch.equal(own[..., 0], rollout["next", "robot", "info", "new_interest"].float())
    torch.testing.assert_close(own.sum(-2), rollout["next", "robot", "reward"][..., 0, :])
    with pytest.raises(ValueError, match="reward"):
        prepare_batch(rollout.copy(), 1.0, reward="mine")
    # the team reward of each ended episode is the sum of the rewards since its start
    rewards = rollout["next", "robot", "reward"][..., 0, 0]
    for env_index in range(2):
        ends = torch.nonzero(done[env_index, :, 0]).flatten()
        assert len(ends) == 1
        expected = float(rewards[env_index, : ends[0] + 1].sum())
        assert episode_rewards(rollout[env_index : env_index + 1]) == [expected]


def test_ppo_updates_lower_the_critic_loss(rollout, tmp_path: Path) -> None:  # noqa: ANN001
    torch.manual_seed(3)
    config = tiny_config(tmp_path)
    actor_gnn, critic_gnn = AggregationGNN(config.model.actor), AggregationGNN(config.model.critic)
    actor = build_actor(actor_gnn, config, 3)
    critic = build_critic(critic_gnn, config, 3)
    loss_module = build_loss(actor, critic, config)
    # the loss trains the networks themselves (train_mappo's optimiser groups rely on it)
    shared = {id(p) for p in loss_module.parameters()}
    assert all(id(p) in shared for p in [*actor_gnn.parameters(), *critic_gnn.parameters()])
    assert len(shared) == len([*actor_gnn.parameters(), *critic_gnn.parameters()])
    data = rollout.copy()
    with torch.no_grad():
        actor(data)  # the behaviour policy's log-probabilities
    data = prepare_batch(data, 1.0)
    with torch.no_grad():
        loss_module.value_estimator(data, params=loss_module.critic_network_params)
    optimizer = torch.optim.Adam(loss_module.parameters(), lr=3e-3)
    first = None
    for _ in range(60):
        losses = loss_module(data.reshape(-1))
        total = losses["loss_objective"] + losses["loss_critic"] + losses["loss_entropy"]
        first = float(losses["loss_critic"].detach()) if first is None else first
        optimizer.zero_grad()
        total.backward()
        optimizer.step()
    assert float(losses["loss_critic"].detach()) < 0.5 * first


def test_mappo_learns_a_tiny_task(tmp_path: Path) -> None:
    config = tiny_config(tmp_path, "collector.n_iters=20", "seed=0")
    summary = train_mappo(config)
    curve = json.loads((tmp_path / "run" / "curve.json").read_text())[1:]  # after iteration 0
    first = np.mean([row["episode_reward"] for row in curve[:4]])
    last = np.mean([row["episode_reward"] for row in curve[-4:]])
    assert summary["iteration"] == 20
    assert last > first + 3.0, (first, last)  # measured: about 4.7 -> 11 on this task
    assert (tmp_path / "run" / "best.pt").is_file()


def test_counterfactual_advantages_are_q_minus_the_policys_mean(tmp_path: Path) -> None:
    """Each robot's advantage: the simulated return of its move minus the sampling policy's
    mean over its moves (masked moves carry no probability), times the reward scale."""
    torch.manual_seed(2)
    env = BatchedCoverageEnv(2, counterfactual_hops=3, **TINY_ENV)
    env.set_seed(8)
    batch = env.rollout(6, break_when_any_done=False).reshape(-1)
    actor = build_actor(AggregationGNN(GNNConfig(kind="linear", hops=3)), tiny_config(tmp_path), 3)
    advantage = counterfactual_advantages(actor, batch, 0.1)  # (12, 3, 1)
    logits = actor(batch.clone())["robot", "logits"].detach()
    allowed = batch["robot", "action_mask"]
    probs = torch.softmax(logits.masked_fill(~allowed, -torch.inf), -1)
    q = batch[COUNTERFACTUAL_KEY]
    action = batch["robot", "action"]
    for row in range(batch.shape[0]):
        for robot in range(3):
            mean = sum(float(probs[row, robot, m] * q[row, robot, m]) for m in range(5))
            expected = 0.1 * (float(q[row, robot, action[row, robot]]) - mean)
            assert float(advantage[row, robot, 0]) == pytest.approx(expected, abs=1e-5)
    assert advantage.abs().max() > 0


def test_all_action_objective_is_the_expected_clipped_surrogate(tmp_path: Path) -> None:
    """At the sampling policy the objective is minus the policy's mean advantage (zero); after
    a step of the weights it is the formula, move by move, with the ratio clipped; its gradient
    reaches the actor."""
    torch.manual_seed(3)
    env = BatchedCoverageEnv(2, counterfactual_hops=3, **TINY_ENV)
    env.set_seed(9)
    batch = env.rollout(6, break_when_any_done=False).reshape(-1)
    gnn = AggregationGNN(GNNConfig(kind="linear", hops=3))
    actor = build_actor(gnn, tiny_config(tmp_path), 3)
    counterfactual_advantages(actor, batch, 0.1, keep_all=True)
    old, advantage = batch[OLD_LOGITS_KEY], batch[ALL_ADVANTAGES_KEY]
    allowed = batch["robot", "action_mask"]
    assert torch.equal(old > -torch.inf, allowed)
    probs = old.softmax(-1)
    # every robot's advantages average to zero under the policy that sampled them
    torch.testing.assert_close((probs * advantage).sum(-1), torch.zeros(12, 3), atol=1e-5, rtol=0)
    start = all_action_objective(actor, batch, 0.1)
    assert abs(float(start.detach())) < 1e-6
    with torch.no_grad():
        for parameter in gnn.parameters():
            parameter.add_(0.5 * torch.randn_like(parameter))
    objective = all_action_objective(actor, batch, 0.1)
    current = actor(batch.clone())["robot", "logits"].detach().masked_fill(~allowed, -torch.inf)
    ratio = torch.where(allowed, (current.log_softmax(-1) - old.log_softmax(-1)).exp(), 1.0)
    scaled = torch.where(allowed, advantage / advantage[allowed].std(), 0.0)
    terms = torch.minimum(ratio * scaled, ratio.clamp(0.9, 1.1) * scaled)
    expected = -(probs * terms).sum(-1).mean()
    torch.testing.assert_close(objective.detach(), expected)
    assert (ratio[allowed] - 1).abs().max() > 0.1  # some ratios are clipped
    objective.backward()
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in gnn.parameters())


def test_counterfactual_advantages_learn_the_tiny_task(tmp_path: Path) -> None:
    config = tiny_config(
        tmp_path, "collector.n_iters=20", "seed=0", "loss.advantage=counterfactual"
    )
    summary = train_mappo(config)
    curve = json.loads((tmp_path / "run" / "curve.json").read_text())[1:]
    first = np.mean([row["episode_reward"] for row in curve[:4]])
    last = np.mean([row["episode_reward"] for row in curve[-4:]])
    assert summary["iteration"] == 20
    assert last > first + 3.0, (first, last)  # measured: about 4.5 -> 12.1 (GAE: 10.6)
    config = tiny_config(
        tmp_path,
        "collector.n_iters=20",
        "seed=0",
        "loss.advantage=counterfactual",
        "loss.all_actions=true",
        f"out={tmp_path / 'all'}",
    )
    train_mappo(config)
    curve = json.loads((tmp_path / "all" / "curve.json").read_text())[1:]
    first = np.mean([row["episode_reward"] for row in curve[:4]])
    last = np.mean([row["episode_reward"] for row in curve[-4:]])
    assert last > first + 3.0, (first, last)  # measured: about 4.5 -> 12.2
    with pytest.raises(ValueError, match="loss.advantage must be one of"):
        tiny_config(tmp_path, "loss.advantage=vtrace")
    with pytest.raises(ValueError, match="loss.all_actions needs loss.advantage=counterfactual"):
        tiny_config(tmp_path, "loss.all_actions=true")
    with pytest.raises(ValueError, match="counterfactual needs the coverage task"):
        tiny_config(tmp_path, "loss.advantage=counterfactual", "env.task=exploration")


def test_ippo_with_ego_actor_runs(tmp_path: Path) -> None:
    config = tiny_config(tmp_path, "algorithm=ippo", "model.actor_input=ego", "collector.n_iters=2")
    summary = train_mappo(config)
    assert summary["iteration"] == 2
    assert summary["observations"] == 2 * 400 * 3


@pytest.mark.parametrize("algorithm", ["mappo", "ippo"])
def test_time_aware_critic_trains(tmp_path: Path, algorithm: str) -> None:
    config = tiny_config(
        tmp_path, f"algorithm={algorithm}", "model.critic_time=true", "collector.n_iters=2"
    )
    summary = train_mappo(config)
    assert summary["iteration"] == 2 and np.isfinite(summary["loss_critic"])
    checkpoint = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=False)
    assert checkpoint["critic_config"]["node_features"] == 5  # 4 node features + steps left


def test_privileged_critic_reads_the_true_map(tmp_path: Path) -> None:
    config = tiny_config(
        tmp_path, "env.task=exploration", "model.critic_input=privileged", "collector.n_iters=2"
    )
    critic = build_critic(AggregationGNN(config.model.critic), config, 3)
    assert critic.in_keys == [("privileged", k) for k in GRAPH_IN]
    timed = tiny_config(tmp_path, "model.critic_input=privileged", "model.critic_time=true")
    assert build_critic(AggregationGNN(timed.model.critic), timed, 3, horizon=10).in_keys[-1] == (
        "privileged",
        "steps_left",
    )
    summary = train_mappo(config)
    assert summary["iteration"] == 2 and np.isfinite(summary["loss_critic"])
    with pytest.raises(ValueError, match="critic_input=privileged needs algorithm=mappo"):
        tiny_config(tmp_path, "algorithm=ippo", "model.critic_input=privileged")
    with pytest.raises(ValueError, match="model.critic_input must be one of"):
        tiny_config(tmp_path, "model.critic_input=truth")


def test_snapshots_keep_the_actor_of_every_evaluation(tmp_path: Path) -> None:
    config = tiny_config(tmp_path, "collector.n_iters=4", "eval.every=2", "snapshots=true")
    train_mappo(config)
    run = tmp_path / "run"
    assert sorted(p.name for p in (run / "steps").iterdir()) == [
        "step_000002.pt",
        "step_000004.pt",
    ]
    curve = {row["iteration"]: row for row in json.loads((run / "curve.json").read_text())}
    last, last_meta = load_model(run / "steps" / "step_000004.pt")
    final, _ = load_model(run / "model.pt")
    for name, tensor in final.state_dict().items():
        assert torch.equal(last.state_dict()[name], tensor), name
    assert last_meta["iteration"] == 4 and last_meta["eval_reward"] == curve[4]["eval_reward"]
    _, meta = load_model(run / "steps" / "step_000002.pt")
    assert meta["eval_reward"] == curve[2]["eval_reward"]


def test_config_errors_name_the_key(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="algorithm"):
        tiny_config(tmp_path, "algorithm=sac")
    with pytest.raises(ValueError, match="multiple of num_envs"):
        tiny_config(tmp_path, "collector.frames_per_batch=30")
    with pytest.raises(ValueError, match="unknown key"):
        tiny_config(tmp_path, "optim.learning_rate=1")
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="no CUDA"):
            train_mappo(tiny_config(tmp_path, "device=cuda"))
    for override, message in (
        ("loss.gamma=1.5", r"loss.gamma must be in \(0, 1\], got 1.5"),
        ("loss.lmbda=-0.1", r"loss.lmbda must be in \[0, 1\], got -0.1"),
        ("loss.clip_epsilon=0", "loss.clip_epsilon must be > 0, got 0"),
        ("optim.lr=0", "optim.lr and optim.critic_lr must be > 0"),
        ("model.temperature=0", "model.temperature must be > 0, got 0"),
        ("eval.every=0", "eval.every and eval.episodes must be >= 1"),
    ):
        with pytest.raises(ValueError, match=message):
            tiny_config(tmp_path, override)


def test_train_mappo_script_smoke_and_resume(tmp_path: Path) -> None:
    """The CI smoke command (on the paper's windows where the map is on disk), then a resume."""
    command = [
        sys.executable,
        str(ROOT / "scripts" / "train_mappo.py"),
        "collector.n_iters=2",
        "collector.frames_per_batch=200",
        f"out={tmp_path / 'smoke'}",
        "eval.episodes=4",
        "progress=false",
    ]
    try:
        paper_map_path()
    except FileNotFoundError:
        command.append("env.map=city")  # CI without the paper's map beside the clone
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(command, capture_output=True, text=True, env=env, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    assert json.loads(done.stdout)["iteration"] == 2
    for name in ("config.yaml", "checkpoint.pt", "best.pt", "model.pt", "curve.json"):
        assert (tmp_path / "smoke" / name).is_file(), name
    assert list((tmp_path / "smoke" / "log").rglob("*.csv"))
    # Resumed in this process (the command line itself ran above).
    command[2] = "collector.n_iters=3"
    done = run_script("train_mappo.py", *command[2:])
    assert done.returncode == 0, done.stderr[-3000:]
    curve = json.loads((tmp_path / "smoke" / "curve.json").read_text())
    assert [row["iteration"] for row in curve] == [0, 1, 2, 3]  # 0: the untrained policy
    bad = run_script("train_mappo.py", *command[2:], "loss.gama=0.9")
    assert bad.returncode != 0 and "gama" in bad.stderr
    # the learning curves of the run: a PNG and a table row from its curve.json
    png = tmp_path / "curves.png"
    plotted = run_script(
        "plot_mappo.py", str(tmp_path / "smoke"), "--line", "BC=80", "--out", str(png)
    )
    assert plotted.returncode == 0, plotted.stderr[-3000:]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    row = next(line for line in plotted.stdout.splitlines() if line.startswith("smoke"))
    evaluations = [r["eval_reward"] for r in curve if "eval_reward" in r]
    assert row.split()[1:] == [
        "3",
        f"{curve[-1]['observations']:.0f}",
        f"{evaluations[-1]:.2f}",
        f"{max(evaluations):.2f}",
    ]
    for args, message in (
        ([str(tmp_path)], "no curve.json"),
        (["--line", "BC=high"], "name=number"),
    ):
        refused = run_script("plot_mappo.py", *args, str(tmp_path / "smoke"), "--out", str(png))
        assert refused.returncode != 0 and message in refused.stderr


def test_print_config_shows_the_settings_and_trains_nothing(tmp_path: Path) -> None:
    """``--print-config`` prints the preset with the overrides applied, as YAML that
    ``--config`` reads back to the same settings, and writes no run folder."""
    preset = str(ROOT / "configs" / "mappo_finetune.yaml")
    overrides = ["loss.gamma=1.0", "model.critic_time=true", f"out={tmp_path / 'run'}"]
    done = run_script("train_mappo.py", "--print-config", "--config", preset, *overrides)
    assert done.returncode == 0, done.stderr[-3000:]
    printed = tmp_path / "printed.yaml"
    printed.write_text(done.stdout)
    expected = configuration.load(MAPPOConfig, preset, overrides)
    assert configuration.load(MAPPOConfig, printed) == expected
    assert expected.loss.gamma == 1.0 and expected.model.critic_time
    assert not (tmp_path / "run").exists()
    bad = run_script("train_mappo.py", "--print-config", "loss.gama=0.9")
    assert bad.returncode != 0 and "gama" in bad.stderr


def test_worker_processes_collect_the_same_budget(tmp_path: Path) -> None:
    config = tiny_config(tmp_path, "collector.workers=2", "collector.n_iters=2", "eval.every=2")
    summary = train_mappo(config)
    assert summary["frames"] == 800 and summary["episodes"] == 2 * 20  # 10-step episodes
    assert np.isfinite(summary["eval_reward"])


def test_temperature_sharpens_sampling_and_keeps_the_argmax(rollout, tmp_path: Path) -> None:  # noqa: ANN001
    torch.manual_seed(4)
    gnn = AggregationGNN(GNNConfig(kind="linear", hops=3))
    plain = build_actor(gnn, tiny_config(tmp_path), 3)(rollout[:, 0].clone())
    sharp = build_actor(gnn, tiny_config(tmp_path, "model.temperature=0.5"), 3)(
        rollout[:, 0].clone()
    )
    torch.testing.assert_close(sharp["robot", "logits"], 2 * plain["robot", "logits"])
    assert torch.equal(sharp["robot", "logits"].argmax(-1), plain["robot", "logits"].argmax(-1))
    with pytest.raises(ValueError, match="temperature"):
        build_actor(gnn, tiny_config(tmp_path, "model.temperature=0"), 3)


def test_anchor_kl_is_the_divergence_from_the_frozen_start(rollout, tmp_path: Path) -> None:  # noqa: ANN001
    torch.manual_seed(5)
    config = tiny_config(tmp_path, "model.temperature=0.5")
    start = AggregationGNN(GNNConfig(kind="linear", hops=3))
    moved = AggregationGNN(GNNConfig(kind="linear", hops=3))
    moved.load_state_dict(start.state_dict())
    anchor = build_actor(start.requires_grad_(False), config, 3)
    actor = build_actor(moved, config, 3)
    batch = rollout.reshape(-1).clone()
    batch.set(ANCHOR_KEY, anchor_log_probs(anchor, batch))
    assert anchor_kl(actor, batch).item() == pytest.approx(0.0, abs=1e-7)
    with torch.no_grad():
        for parameter in moved.parameters():
            parameter.add_(0.3 * torch.randn_like(parameter))
    kl = anchor_kl(actor, batch)
    # the formula, on the logits the two actors write (masked actions carry no probability)
    allowed = batch["robot", "action_mask"]

    def log_probs(module) -> torch.Tensor:  # noqa: ANN001
        logits = module(batch.clone())["robot", "logits"].detach()
        return torch.log_softmax(logits.masked_fill(~allowed, -torch.inf), -1)

    p_log, q_log = log_probs(anchor), log_probs(actor)
    terms = torch.where(allowed, p_log.exp() * (p_log - q_log), torch.zeros_like(p_log))
    torch.testing.assert_close(kl.detach(), terms.sum(-1).mean())
    assert kl.item() > 0
    kl.backward()
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in moved.parameters())
    assert all(p.grad is None for p in start.parameters())


def test_anchor_keeps_fine_tuning_near_the_start(rollout, tmp_path: Path) -> None:  # noqa: ANN001
    torch.manual_seed(6)
    init = tmp_path / "init.pt"
    save_model(init, AggregationGNN(GNNConfig(kind="linear", hops=3)), {})
    common = ("collector.n_iters=3", "eval.every=3", f"init={init}", "optim.lr=0.01", "seed=1")
    config = tiny_config(tmp_path)
    start = build_actor(load_model(init)[0], config, 3)
    batch = rollout.reshape(-1).clone()
    batch.set(ANCHOR_KEY, anchor_log_probs(start, batch))
    divergence = {}
    for coef in (0.0, 30.0):
        out = tmp_path / f"anchor_{coef}"
        train_mappo(tiny_config(tmp_path, *common, f"out={out}", f"loss.anchor_coef={coef}"))
        curve = json.loads((out / "curve.json").read_text())
        assert ("kl_anchor" in curve[-1]) == (coef > 0)
        end = build_actor(load_model(out / "model.pt")[0], config, 3)
        with torch.no_grad():
            divergence[coef] = float(anchor_kl(end, batch))
    # measured: 0.046 without the anchor, 1e-5 with it
    assert 0 < divergence[30.0] < 0.1 * divergence[0.0], divergence
    with pytest.raises(ValueError, match="needs init"):
        tiny_config(tmp_path, "loss.anchor_coef=1")
    with pytest.raises(ValueError, match="anchor_coef must be >= 0"):
        tiny_config(tmp_path, f"init={init}", "loss.anchor_coef=-1")


def test_same_seed_trains_the_same_actor_bit_for_bit(tmp_path: Path) -> None:
    # the collector's first episodes are seeded too (it resets its environment when built)
    models = []
    for name in ("a", "b"):
        train_mappo(
            tiny_config(tmp_path, "collector.n_iters=2", "eval.every=2", f"out={tmp_path / name}")
        )
        models.append(load_model(tmp_path / name / "model.pt")[0])
    for first, second in zip(models[0].parameters(), models[1].parameters(), strict=True):
        assert torch.equal(first, second)
    curves = [json.loads((tmp_path / n / "curve.json").read_text()) for n in ("a", "b")]
    assert [r.get("episode_reward") for r in curves[0]] == [
        r.get("episode_reward") for r in curves[1]
    ]


def test_a_run_from_before_a_new_key_resumes(tmp_path: Path) -> None:
    import yaml

    train_mappo(tiny_config(tmp_path, "collector.n_iters=1", "eval.every=1"))
    saved = tmp_path / "run" / "config.yaml"
    record = yaml.safe_load(saved.read_text())
    del record["loss"]["anchor_coef"]  # as written before session 31
    saved.write_text(yaml.safe_dump(record))
    summary = train_mappo(tiny_config(tmp_path, "collector.n_iters=2", "eval.every=1"))
    assert summary["iteration"] == 2
    with pytest.raises(ValueError, match="loss.gamma"):
        train_mappo(tiny_config(tmp_path, "collector.n_iters=3", "loss.gamma=0.5"))


def test_grow_actor_fine_tunes_a_grown_copy_of_the_init_model(tmp_path: Path) -> None:
    torch.manual_seed(7)
    start = AggregationGNN(GNNConfig(kind="nonlinear", hops=3, hidden=8))
    init = tmp_path / "init.pt"
    save_model(init, start, {})
    grown = ("model.actor.kind=nonlinear", "model.actor.hidden=12", "model.actor.per_hop=true")
    common = (f"init={init}", "collector.n_iters=1", "eval.every=1", "model.actor.kind=nonlinear")
    config = tiny_config(tmp_path, *common, *grown, "model.grow_actor=true")
    train_mappo(config)
    out = Path(config.out)
    trained, _ = load_model(out / "model.pt")
    assert trained.config == GNNConfig(kind="nonlinear", hops=3, hidden=12, per_hop=True)
    # iteration 0 evaluates the grown copy, which plays exactly as the init model
    curve = json.loads((out / "curve.json").read_text())
    seeds = range(config.eval.seed, config.eval.seed + config.eval.episodes)
    played = evaluate(CoverageEnv(**config.env), GNNPolicy(start, centralized=True), seeds)
    assert curve[0]["eval_reward"] == played.mean
    with pytest.raises(ValueError, match="grow_actor needs init"):
        tiny_config(tmp_path, *grown, "model.grow_actor=true")
    smaller = tiny_config(
        tmp_path,
        *common,
        f"out={tmp_path / 'small'}",
        "model.actor.hidden=4",
        "model.grow_actor=true",
    )
    with pytest.raises(ValueError, match="model.grow_actor: cannot grow .*init.pt"):
        train_mappo(smaller)
