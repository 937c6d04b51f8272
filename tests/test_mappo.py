"""MAPPO: actor and critic modules, the batch preparation, learning on a tiny task, the script."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("torchrl")

from helpers import run_cli, run_script  # noqa: E402

from marl_cover.agents.cli import options as configuration  # noqa: E402
from marl_cover.agents.evaluation.episodes import evaluate  # noqa: E402
from marl_cover.agents.models.actors import EgoGraphLogits, StateLogits  # noqa: E402
from marl_cover.agents.models.checkpoints import load_model, save_model  # noqa: E402
from marl_cover.agents.models.gnn import AggregationGNN, GNNConfig  # noqa: E402
from marl_cover.agents.models.policy import GNNPolicy  # noqa: E402
from marl_cover.agents.models.value import EgoValue, StateValue  # noqa: E402
from marl_cover.agents.training.batched_env import BatchedCoverageEnv  # noqa: E402
from marl_cover.agents.training.mappo import MAPPOConfig, train_mappo  # noqa: E402
from marl_cover.agents.training.mappo_parts import (  # noqa: E402
    build_actor,
    build_critic,
    build_loss,
    episode_rewards,
    prepare_batch,
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
    tiny = [f"env.{key}={value}" for key, value in TINY_ENV.items()]
    return configuration.load(MAPPOConfig, None, [*tiny, *base, *overrides])


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


def test_ippo_with_ego_actor_runs(tmp_path: Path) -> None:
    config = tiny_config(tmp_path, "algorithm=ippo", "model.actor_input=ego", "collector.n_iters=2")
    summary = train_mappo(config)
    assert summary["iteration"] == 2
    assert summary["observations"] == 2 * 400 * 3


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
    with pytest.raises(ValueError, match="learning_rate"):
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
        ("env.num_robots=0", "num_robots must be >= 1, got 0"),
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
    done = subprocess.run(command, capture_output=True, text=True, check=False)
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
    bad = run_cli("train-mappo", *command[2:], "loss.gama=0.9")
    assert bad.returncode != 0 and "gama" in bad.stderr
    # the learning curves of the run: a PNG and a table row from its curve.json
    png = tmp_path / "curves.png"
    plotted = run_cli("plot-mappo", f"runs=[{tmp_path / 'smoke'}]", "lines={BC: 80}", f"out={png}")
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
        ([f"runs=[{tmp_path}]"], "no curve.json"),
        (["lines={BC: high}"], "(full_key: lines.BC)"),
    ):
        refused = run_cli("plot-mappo", *args, f"out={png}")
        assert refused.returncode != 0 and message in refused.stderr


def test_print_config_shows_the_settings_and_trains_nothing(tmp_path: Path) -> None:
    """``--print-config`` prints the preset with the overrides applied, as YAML that
    ``--config`` reads back to the same settings, and writes no run folder."""
    preset = "mappo_finetune"
    overrides = ["loss.gamma=1.0", "model.temperature=0.5", f"out={tmp_path / 'run'}"]
    done = run_cli("train-mappo", "--print-config", "--config", preset, *overrides)
    assert done.returncode == 0, done.stderr[-3000:]
    printed = tmp_path / "printed.yaml"
    printed.write_text(done.stdout)
    expected = configuration.load(MAPPOConfig, preset, overrides)
    assert configuration.load(MAPPOConfig, printed) == expected
    assert expected.loss.gamma == 1.0 and expected.model.temperature == 0.5
    assert not (tmp_path / "run").exists()
    bad = run_cli("train-mappo", "--print-config", "loss.gama=0.9")
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
    del record["loss"]["reward"]  # as a run written before the key existed
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
    env = CoverageEnv(**config.env.as_kwargs())
    played = evaluate(env, GNNPolicy(start, centralized=True), seeds)
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
