"""Behaviour cloning: collation, TorchRL modules, the training loop, resume, DAgger, configs."""

from __future__ import annotations

import numpy as np
import pytest

import marl_cover

torch = pytest.importorskip("torch")
pytest.importorskip("torchrl")

from helpers import run_cli  # noqa: E402

from marl_cover.agents.baselines.greedy import CentralizedGreedyPolicy  # noqa: E402
from marl_cover.agents.cli import options as configuration  # noqa: E402
from marl_cover.agents.models import AggregationGNN, GNNConfig  # noqa: E402
from marl_cover.agents.models.actors import EgoGraphLogits, make_actor  # noqa: E402
from marl_cover.agents.models.checkpoints import average_models, load_model, save_model  # noqa: E402
from marl_cover.agents.models.logits import action_logits, centralized_logits  # noqa: E402
from marl_cover.agents.models.policy import GNNPolicy  # noqa: E402
from marl_cover.agents.training.bc import BCConfig, DaggerConfig, train_bc, validate  # noqa: E402
from marl_cover.agents.training.data import GraphTable, collate_states, episode_transitions  # noqa: E402
from marl_cover.agents.training.datasets import record_episode, write_shard  # noqa: E402

SMALL_ENV = {"map": "city", "city_size": 90, "hops": 3, "max_steps": 12}


class GreedyRecorder:
    """Greedy with ``act_env``, as the dataset recorder expects of an expert."""

    def __init__(self, hops: int) -> None:
        self.greedy = CentralizedGreedyPolicy(hops, fallback="random")

    def reset(self, seed: int) -> None:
        self.greedy.reset(seed)

    def act_env(self, env) -> dict[str, int]:  # noqa: ANN001
        actions = self.greedy.act_state(env.state())
        return dict(zip(env.possible_agents, np.asarray(actions).tolist(), strict=True))


def record(seeds: range, **env_overrides):  # noqa: ANN201
    env = marl_cover.parallel_env(**{**SMALL_ENV, **env_overrides})
    return [record_episode(env, GreedyRecorder(env.config.hops), seed) for seed in seeds]


@pytest.mark.parametrize(
    ("task", "time_horizon"), [("coverage", None), ("exploration", None), ("coverage", 40)]
)
def test_collated_batches_are_the_environment_states(task: str, time_horizon: int | None) -> None:
    """One flat graph of sampled transitions gives each state's centralized logits (in
    exploration: of the discovered graph, rebuilt from the recorded positions; with a
    ``time_horizon``, the clock of the state too)."""
    torch.manual_seed(0)
    model = AggregationGNN(GNNConfig(kind="nonlinear", hops=3, time_horizon=time_horizon))
    episodes = record(range(3), num_robots=3, task=task)
    max_nodes = max(e.graph.num_nodes for e in episodes) + 5  # padding must not matter
    table = GraphTable([e.graph for e in episodes], max_nodes)
    sensor = 22.0 if task == "exploration" else None
    data = episode_transitions(episodes, max_nodes, sensor_range=sensor)
    assert len(data) == sum(e.num_steps for e in episodes)
    picks = torch.tensor([0, 5, 13, 30, 11])
    batch = data[picks]
    with torch.no_grad():
        *graph, action_edges = collate_states(batch, table, time_horizon, SMALL_ENV["max_steps"])
        logits = action_logits(model, tuple(graph), action_edges)
    env = marl_cover.parallel_env(**SMALL_ENV, num_robots=3, task=task)
    if time_horizon is not None:  # every node's fifth feature is the state's clock
        nodes = graph[0].view(len(picks), -1, 5)
        steps_left = SMALL_ENV["max_steps"] - batch["step"]
        assert torch.equal(
            nodes[..., 4], (steps_left / time_horizon).view(-1, 1).expand_as(nodes[..., 4])
        )
    shape = env._ego_shape
    offsets = np.cumsum([0] + [e.num_steps for e in episodes])
    for row, index in enumerate(picks.tolist()):
        episode_index = int(np.searchsorted(offsets, index, side="right") - 1)
        episode, step = episodes[episode_index], index - offsets[episode_index]
        env.reset(seed=episode.seed)
        for t in range(step):  # replay to the stored state
            env.step(dict(zip(env.possible_agents, episode.actions[t].tolist(), strict=True)))
        assert np.array_equal(env.snapshot().robot_node, episode.robot_node[step])
        rebuilt = episode.observations(
            step, 3, shape, sensor_range=sensor, max_steps=SMALL_ENV["max_steps"]
        )
        for key, value in env.observe_batch().items():
            np.testing.assert_array_equal(rebuilt[key], value, err_msg=key)
        state = {k: torch.as_tensor(v) for k, v in env.state().items()}
        with torch.no_grad():
            expected = centralized_logits(model, state)
        torch.testing.assert_close(logits[3 * row : 3 * row + 3], expected, atol=1e-5, rtol=0)
        assert torch.equal(batch["action"][row], torch.as_tensor(episode.actions[step]).long())


def test_the_torchrl_actor_never_samples_a_masked_action() -> None:
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

    torch.manual_seed(0)
    env = PettingZooWrapper(
        marl_cover.parallel_env(**SMALL_ENV), return_state=False, use_mask=False, seed=0
    )
    actor = make_actor(
        AggregationGNN(GNNConfig(hops=3)),
        observation_key=("robot", "observation"),
        action_key=("robot", "action"),
        mask_key=("robot", "action_mask"),
    )
    rollout = env.rollout(12, policy=actor)
    actions = rollout["robot", "action"]  # (T, R)
    masks = rollout["robot", "action_mask"]  # (T, R, 5) bool
    assert actions.shape == (12, 4)
    assert masks.gather(-1, actions.unsqueeze(-1)).all()
    assert torch.isfinite(rollout["robot", "sample_log_prob"]).all()
    # the module accepts any leading batch shape: (T, R) here
    observation = rollout["robot", "observation"]
    logits, mask = EgoGraphLogits(AggregationGNN(GNNConfig(hops=3)))(
        *(observation[key] for key in ("nodes", "edge_index", "edge_attr", "edge_mask")), masks
    )
    assert logits.shape == mask.shape == (12, 4, 5) and torch.equal(mask, masks)
    # a model with a clock reads each robot's steps_left from its observation
    timed = make_actor(
        AggregationGNN(GNNConfig(hops=3, time_horizon=12)),
        observation_key=("robot", "observation"),
        action_key=("robot", "action"),
        mask_key=("robot", "action_mask"),
    )
    assert ("robot", "observation", "steps_left") in timed.in_keys
    assert torch.equal(observation["steps_left"][:, 0].view(-1), 12 - torch.arange(12))
    timed_rollout = env.rollout(12, policy=timed)
    chosen = timed_rollout["robot", "action"].unsqueeze(-1)
    assert timed_rollout["robot", "action_mask"].gather(-1, chosen).all()


@pytest.mark.parametrize(
    ("kind", "time_horizon"), [("linear", None), ("nonlinear", None), ("nonlinear", 12)]
)
def test_decentralized_and_centralized_policies_act_alike(
    kind: str, time_horizon: int | None
) -> None:
    torch.manual_seed(1)
    config = GNNConfig(kind=kind, hops=3, time_horizon=time_horizon)
    model = AggregationGNN(config).double()  # no float32 near-ties
    local, central = GNNPolicy(model), GNNPolicy(model, centralized=True)
    env = marl_cover.parallel_env(**SMALL_ENV, num_robots=5)
    observations, _ = env.reset(seed=3)
    while env.agents:
        actions = local.act(observations)
        assert list(central.act_state(env.state())) == [actions[a] for a in env.possible_agents]
        observations, *_ = env.step(actions)


def test_model_files_round_trip_and_bad_files_are_named(tmp_path) -> None:
    model = AggregationGNN(GNNConfig(kind="linear", hops=4, hidden=8))
    save_model(tmp_path / "m.pt", model, {"seed": 7})
    loaded, metadata = load_model(tmp_path / "m.pt")
    assert loaded.config == model.config and metadata == {"seed": 7}
    for a, b in zip(loaded.state_dict().values(), model.state_dict().values(), strict=True):
        assert torch.equal(a, b)
    torch.save({"weights": 1}, tmp_path / "bad.pt")
    with pytest.raises(ValueError, match="bad.pt: not a model file"):
        load_model(tmp_path / "bad.pt")
    with pytest.raises(FileNotFoundError, match="missing.pt"):
        load_model(tmp_path / "missing.pt")
    (tmp_path / "empty.pt").write_bytes(b"")
    (tmp_path / "notes.pt").write_text("# notes\n")
    for name, error in (("empty.pt", "EOFError"), ("notes.pt", "UnpicklingError")):
        with pytest.raises(ValueError, match=rf"{name}: not a readable model file \({error}: "):
            load_model(tmp_path / name)


def test_averaged_models_hold_the_mean_weights(tmp_path) -> None:
    config = GNNConfig(kind="nonlinear", hops=2, hidden=4)
    torch.manual_seed(0)
    models = [AggregationGNN(config) for _ in range(3)]
    for i, model in enumerate(models):
        save_model(tmp_path / f"m{i}.pt", model, {"seed": i})
    paths = [tmp_path / f"m{i}.pt" for i in range(3)]
    average, metadata = average_models(paths)
    assert metadata == {"seed": 0, "average_of": [str(p) for p in paths]}
    for key, value in average.state_dict().items():
        expected = (sum(m.state_dict()[key] for m in models)) / 3
        torch.testing.assert_close(value, expected, rtol=0, atol=1e-7)
    assert (
        average_models(paths[:1] * 2)[0]
        .state_dict()["readout.weight"]
        .equal(models[0].state_dict()["readout.weight"])
    )
    save_model(tmp_path / "wide.pt", AggregationGNN(GNNConfig(kind="nonlinear", hops=2)), {})
    with pytest.raises(ValueError, match="wide.pt holds a .* network, not the"):
        average_models([paths[0], tmp_path / "wide.pt"])
    with pytest.raises(ValueError, match="at least two model files"):
        average_models(paths[:1])
    refused = run_cli("average", f"files=[{paths[0]}]", f"out={tmp_path / 'out.pt'}")
    assert refused.returncode != 0 and "Traceback" not in refused.stderr
    assert "averaging needs at least two model files, got 1" in refused.stderr
    assert not (tmp_path / "out.pt").exists()


def test_configs_reject_unknown_keys_and_read_sections(tmp_path) -> None:
    config = configuration.load(BCConfig, None, ["model.kind=linear", "model.hops=7", "steps=5"])
    assert config.model == GNNConfig(kind="linear", hops=7) and config.steps == 5
    with pytest.raises(ValueError, match="learning_rate"):
        configuration.load(BCConfig, None, ["learning_rate=0.1"])
    with pytest.raises(ValueError, match=r"model.*width"):
        configuration.load(BCConfig, None, ["model.width=3"])
    preset = tmp_path / "preset.yaml"
    preset.write_text("model:\n  hops: 5\n  kernel: 3\n")
    with pytest.raises(ValueError, match=r"preset.yaml.*kernel"):
        configuration.load(BCConfig, preset)


def test_configs_reject_values_of_the_wrong_type(tmp_path) -> None:
    with pytest.raises(ValueError, match=r"'1.5'.*Integer.*full_key: steps"):
        configuration.load(BCConfig, None, ["steps=1.5"])
    with pytest.raises(ValueError, match=r"'many'.*Integer.*full_key: model.hops"):
        configuration.load(BCConfig, None, ["model.hops=many"])
    preset = tmp_path / "typo.yaml"
    preset.write_text("lr: fast\n")
    with pytest.raises(ValueError, match=r"typo.yaml: Value 'fast'.*Float.*full_key: lr"):
        configuration.load(BCConfig, preset)
    assert configuration.load(BCConfig, None, ["lr=1"]).lr == 1  # an integer is a number


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("lr=0", "lr must be > 0, got 0"),
        ("lr_decay=1.5", r"lr_decay must be in \(0, 1\], got 1.5"),
        ("select_episodes=0", "select_episodes must be >= 1, got 0"),
        ("threads=0", "threads must be >= 1, got 0"),
        ("dagger.beta=2", r"dagger.beta must be in \[0, 1\], got 2"),
        ("dagger.rounds=-1", "dagger.rounds and dagger.steps must be >= 0"),
        ("dagger.episodes=0", "dagger.episodes must be >= 1, got 0"),
        ("model.node_features=0", "node_features and edge_features must be >= 1"),
    ],
)
def test_configs_name_values_out_of_range(override: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        configuration.load(BCConfig, None, [override])


def small_dataset(folder) -> None:  # noqa: ANN001
    episodes = record(range(12))
    write_shard(folder / "shard_00000.npz", episodes[:6])
    write_shard(folder / "shard_00001.npz", episodes[6:])


def small_config(tmp_path, out: str, **overrides) -> BCConfig:  # noqa: ANN001
    values = {
        "dataset": str(tmp_path / "data"),
        "out": str(tmp_path / out),
        "model": GNNConfig(kind="nonlinear", hops=3, hidden=8),
        "env": SMALL_ENV,
        "batch_size": 8,
        "steps": 120,
        "val_every": 60,
        "val_fraction": 0.25,
        "select_episodes": 2,
        "holdout_seeds": [0, 2],
        "logger": "csv",
        "progress": False,
        **overrides,
    }
    return BCConfig(**values)


def test_behaviour_cloning_lowers_the_loss_and_resumes_exactly(tmp_path) -> None:
    small_dataset(tmp_path / "data")
    config = small_config(tmp_path, "whole")
    torch.manual_seed(config.seed)
    untrained = AggregationGNN(config.model)
    summary = train_bc(config)
    assert summary["train_episodes"] == 8 and summary["val_episodes"] == 2  # seeds 0, 1 held out
    from marl_cover.agents.training.bc import split_episodes

    _, val = split_episodes(config)
    max_nodes = max(e.graph.num_nodes for e in val)
    table = GraphTable([e.graph for e in val], max_nodes)
    before = validate(untrained, episode_transitions(val, max_nodes), table)["val_cross_entropy"]
    assert summary["val_cross_entropy"] < before - 0.1
    assert (tmp_path / "whole" / "log" / "scalars" / "val_cross_entropy.csv").exists()
    for name in ("best.pt", "model.pt", "checkpoint.pt", "config.yaml", "summary.json"):
        assert (tmp_path / "whole" / name).exists()
    snapshots = sorted(p.name for p in (tmp_path / "whole" / "steps").iterdir())
    assert snapshots == ["step_000060.pt", "step_000120.pt"]  # one per validation
    last, info = load_model(tmp_path / "whole" / "steps" / "step_000120.pt")
    final, _ = load_model(tmp_path / "whole" / "model.pt")
    assert info["step"] == 120 and info["val_cross_entropy"] == summary["val_cross_entropy"]
    for a, b in zip(last.state_dict().values(), final.state_dict().values(), strict=True):
        assert torch.equal(a, b)

    # interrupted at step 60, then resumed to 120: the same weights as one run
    train_bc(small_config(tmp_path, "parts", steps=60))
    resumed = train_bc(small_config(tmp_path, "parts"))
    assert resumed["step"] == 120
    whole, _ = load_model(tmp_path / "whole" / "model.pt")
    parts, _ = load_model(tmp_path / "parts" / "model.pt")
    for a, b in zip(whole.state_dict().values(), parts.state_dict().values(), strict=True):
        assert torch.equal(a, b)
    with pytest.raises(ValueError, match="other settings"):
        train_bc(small_config(tmp_path, "parts", batch_size=4))


@pytest.mark.parametrize(
    ("name", "hidden", "tolerance"), [("per_hop", 8, 0.0), ("per_hop_wider", 12, 1e-6)]
)
def test_a_smaller_model_starts_a_grown_run(tmp_path, name, hidden, tolerance) -> None:
    small_dataset(tmp_path / "data")
    train_bc(small_config(tmp_path, "shared", steps=30, val_every=30))
    source = str(tmp_path / "shared" / "model.pt")
    grown_config = GNNConfig(kind="nonlinear", hops=3, hidden=hidden, per_hop=True)
    train_bc(small_config(tmp_path, name, init=source, model=grown_config, steps=0))
    shared, _ = load_model(source)
    grown, _ = load_model(tmp_path / name / "model.pt")
    assert grown.config == grown_config
    env = marl_cover.parallel_env(**SMALL_ENV)
    env.reset(seed=3)
    state = {k: torch.as_tensor(v) for k, v in env.state().items()}
    torch.testing.assert_close(
        centralized_logits(grown, state),
        centralized_logits(shared, state),
        atol=tolerance,
        rtol=0,
    )
    with pytest.raises(ValueError, match="nor one that can grow into it"):
        narrower = GNNConfig(kind="nonlinear", hops=3, hidden=4, per_hop=True)
        train_bc(small_config(tmp_path, "narrower", init=source, model=narrower, steps=0))


def test_dagger_labels_the_states_the_learner_visits(tmp_path) -> None:
    pytest.importorskip("pyvrp")
    from marl_cover.agents.training.datasets import read_shard

    small_dataset(tmp_path / "data")
    dagger = DaggerConfig(rounds=1, episodes=2, beta=0.0, steps=20, iterations=30, seed=500)
    summary = train_bc(small_config(tmp_path, "dagger", steps=40, val_every=30, dagger=dagger))
    assert summary["step"] == 60
    episodes = read_shard(tmp_path / "dagger" / "dagger" / "shard_00000.npz")
    assert [e.seed for e in episodes] == [500, 501]
    from marl_cover.agents.experts import RoutingExpert

    env = marl_cover.parallel_env(**SMALL_ENV)
    for episode in episodes:
        assert episode.actions.shape == (SMALL_ENV["max_steps"], 4)
        env.reset(seed=episode.seed)
        assert np.array_equal(env.snapshot().robot_node, episode.robot_node[0])
        expert = RoutingExpert(max_iterations=30, seed=episode.seed)
        assert np.array_equal(expert.act_snapshot(env.snapshot()), episode.actions[0])
        masks = np.concatenate(
            [episode.robot_node[:-1, :, None], episode.graph.neighbors[episode.robot_node[:-1]]],
            axis=-1,
        )
        labels = np.take_along_axis(masks, episode.actions[..., None].astype(int), -1)
        assert (labels >= 0).all()  # every label is a legal move


def test_dagger_can_label_with_a_receding_expert_blind_to_the_clock(tmp_path) -> None:
    pytest.importorskip("pyvrp")
    from marl_cover.agents.experts import RoutingExpert
    from marl_cover.agents.training.datasets import read_shard

    small_dataset(tmp_path / "data")
    dagger = DaggerConfig(
        rounds=1, episodes=1, beta=0.0, steps=10, iterations=30, seed=700,
        expert_mode="receding", expert_horizon=20, expert_clock=False,
    )  # fmt: skip
    train_bc(small_config(tmp_path, "blind", steps=10, val_every=10, dagger=dagger))
    (episode,) = read_shard(tmp_path / "blind" / "dagger" / "shard_00000.npz")
    env = marl_cover.parallel_env(**SMALL_ENV)
    env.reset(seed=episode.seed)
    expert = RoutingExpert(mode="receding", horizon=20, clock=False, max_iterations=30, seed=700)
    assert np.array_equal(expert.act_snapshot(env.snapshot()), episode.actions[0])
    # the shard keeps every move the expert rated as good as its label (dagger's ties)
    assert np.array_equal(episode.accept[0], expert.accept)
    assert episode.accept.shape == episode.actions.shape
    assert ((episode.accept.astype(np.int64) >> episode.actions) & 1).all()
    for bad, message in [
        ({"expert_mode": "closed"}, "expert_mode"),
        ({"expert_mode": "receding"}, "expert_horizon"),
        ({"expert_clock": False}, "expert_clock=false needs"),
        ({"expert_information": "partial"}, "expert_information must be"),
        ({"expert_mode": "gnn"}, "expert_mode must be 'open_loop' or 'receding'"),
    ]:
        with pytest.raises(ValueError, match=message):
            DaggerConfig(**bad)
    with pytest.raises(ValueError, match="clock=False needs mode 'receding'"):
        RoutingExpert(clock=False)


def test_more_dagger_rounds_continue_a_finished_run(tmp_path) -> None:
    pytest.importorskip("pyvrp")
    import yaml

    small_dataset(tmp_path / "data")

    def config(out: str, rounds: int, **dagger) -> BCConfig:  # noqa: ANN003
        values = {"episodes": 1, "beta": 0.0, "steps": 10, "iterations": 30, "seed": 900}
        rounds_config = DaggerConfig(rounds=rounds, fraction=0.5, **{**values, **dagger})
        return small_config(tmp_path, out, steps=10, val_every=10, dagger=rounds_config)

    train_bc(config("whole", 2))
    train_bc(config("parts", 1))
    # a run saved before the expert_* keys existed reads them as their defaults
    saved = tmp_path / "parts" / "config.yaml"
    record = yaml.safe_load(saved.read_text())
    for key in ("expert_mode", "expert_horizon", "expert_clock"):
        del record["dagger"][key]
    saved.write_text(yaml.safe_dump(record))
    resumed = train_bc(config("parts", 2))
    assert resumed["step"] == 30
    assert len(list((tmp_path / "parts" / "dagger").glob("shard_*.npz"))) == 2
    whole, _ = load_model(tmp_path / "whole" / "model.pt")
    parts, _ = load_model(tmp_path / "parts" / "model.pt")
    for a, b in zip(whole.state_dict().values(), parts.state_dict().values(), strict=True):
        assert torch.equal(a, b)
    with pytest.raises(ValueError, match=r"other settings \(\['dagger.episodes'\]\)"):
        train_bc(config("parts", 3, episodes=2))


def test_dagger_can_roll_out_on_another_map_and_team(tmp_path) -> None:
    pytest.importorskip("pyvrp")
    from marl_cover.agents.evaluation.episodes import evaluate
    from marl_cover.agents.training.bc import Part, batch_loss
    from marl_cover.agents.training.datasets import read_shard

    small_dataset(tmp_path / "data")
    larger = {"num_robots": 6, "max_steps": 15, "city_size": 120}
    dagger = DaggerConfig(
        rounds=1, episodes=2, beta=0.0, steps=10, iterations=30, seed=800, fraction=0.5,
        env=larger,
    )  # fmt: skip
    config = small_config(
        tmp_path, "apart", steps=10, val_every=10, dagger=dagger, select_env={"num_robots": 6}
    )
    assert train_bc(config)["step"] == 20
    episodes = read_shard(tmp_path / "apart" / "dagger" / "shard_00000.npz")
    env = marl_cover.parallel_env(**{**SMALL_ENV, **larger})
    for episode in episodes:
        assert episode.actions.shape == (15, 6)  # the roll-out env's length and team
        env.reset(seed=episode.seed)
        assert episode.graph.num_nodes == env.snapshot().graph.num_nodes
    # the selection episodes ran on select_env: best.pt reproduces its recorded score
    best, metadata = load_model(tmp_path / "apart" / "best.pt")
    select = marl_cover.parallel_env(**{**SMALL_ENV, "num_robots": 6})
    seeds = range(config.select_seed, config.select_seed + config.select_episodes)
    score = evaluate(select, GNNPolicy(best, centralized=True), seeds).mean
    assert score == metadata["select_reward"]

    # a batch in two parts: the mean cross-entropy over the robots of both
    windows = record(range(2))
    table = GraphTable([e.graph for e in windows])
    own_table = GraphTable([e.graph for e in episodes])
    first = Part(episode_transitions(windows, table.max_nodes)[:5], table, 12)
    second = Part(episode_transitions(episodes, own_table.max_nodes)[:3], own_table, 15)
    both, _ = batch_loss(best, first.batch, table, max_steps=12, extra=second)
    one, _ = batch_loss(best, first.batch, table, max_steps=12)
    two, _ = batch_loss(best, second.batch, own_table, max_steps=15)
    assert both.item() == pytest.approx((5 * 4 * one.item() + 3 * 6 * two.item()) / 38, rel=1e-5)
    with pytest.raises(ValueError, match="dagger.env needs dagger.fraction"):
        DaggerConfig(env=larger)


def test_dagger_fraction_fixes_the_share_of_learner_states_in_a_batch(
    tmp_path, monkeypatch
) -> None:
    from tensordict import TensorDict

    from marl_cover.agents.training.bc import make_buffer, mixed_batch

    dataset, own = make_buffer(100), make_buffer(100)
    dataset.extend(TensorDict({"x": torch.arange(40)}, batch_size=[40]))
    assert mixed_batch(dataset, own, 8, 3)["x"].shape == (8,)  # own is still empty
    own.extend(TensorDict({"x": 1000 + torch.arange(10)}, batch_size=[10]))
    for _ in range(5):
        x = mixed_batch(dataset, own, 8, 3)["x"]
        assert (x[:5] < 40).all() and (x[5:] >= 1000).all()
    with pytest.raises(ValueError, match="dagger.fraction"):
        DaggerConfig(fraction=1.0)
    # a run with a DAgger share resumes as if never interrupted
    pytest.importorskip("pyvrp")
    small_dataset(tmp_path / "data")
    dagger = DaggerConfig(rounds=1, episodes=2, beta=0.0, steps=20, iterations=30, fraction=0.5)
    whole = train_bc(small_config(tmp_path, "whole", steps=20, val_every=10, dagger=dagger))
    assert whole["step"] == 40
    import marl_cover.agents.training.bc as bc

    calls, real = [], bc.batch_loss

    def interrupted(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        calls.append(1)
        if len(calls) == 36:  # validations count too: step 34, after the checkpoint of step 30
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(bc, "batch_loss", interrupted)
    with pytest.raises(KeyboardInterrupt):
        train_bc(small_config(tmp_path, "parts", steps=20, val_every=10, dagger=dagger))
    monkeypatch.setattr(bc, "batch_loss", real)
    resumed = train_bc(small_config(tmp_path, "parts", steps=20, val_every=10, dagger=dagger))
    assert resumed["step"] == 40
    one, _ = load_model(tmp_path / "whole" / "model.pt")
    two, _ = load_model(tmp_path / "parts" / "model.pt")
    for a, b in zip(one.state_dict().values(), two.state_dict().values(), strict=True):
        assert torch.equal(a, b)

    import json

    from helpers import run_cli

    small_dataset(tmp_path / "data")
    command = [
        f"dataset={tmp_path / 'data'}",
        f"out={tmp_path / 'run'}",
        "model.hops=2",
        "steps=20",
        "val_every=10",
        "select_episodes=1",
        "holdout_seeds=[0,1]",
        "env.map=city",
        "env.city_size=90",
        "progress=false",
    ]
    result = run_cli("train-bc", *command)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["step"] == 20
    config = (tmp_path / "run" / "config.yaml").read_text()
    assert "kind: nonlinear" in config and "hops: 2" in config  # preset + override
    bad = run_cli("train-bc", command[0], "model.depth=3")
    assert bad.returncode != 0 and "depth" in bad.stderr


def test_dagger_reuse_adds_another_runs_labelled_states(tmp_path, monkeypatch) -> None:
    pytest.importorskip("pyvrp")
    import marl_cover.agents.training.bc as bc
    from marl_cover.agents.training.datasets import read_shard

    small_dataset(tmp_path / "data")
    dagger = DaggerConfig(rounds=1, episodes=2, beta=0.0, steps=10, iterations=30, fraction=0.5)
    train_bc(small_config(tmp_path, "first", steps=10, val_every=10, dagger=dagger))
    folder = tmp_path / "first" / "dagger"
    reused_steps = sum(e.num_steps for e in read_shard(folder / "shard_00000.npz"))
    assert reused_steps == 2 * SMALL_ENV["max_steps"]

    sizes, real = [], bc.mixed_batch

    def recording(buffer, own, batch_size, own_size):  # noqa: ANN001, ANN202
        sizes.append(len(own))
        return real(buffer, own, batch_size, own_size)

    monkeypatch.setattr(bc, "mixed_batch", recording)
    # no rounds of its own: the reused states fill the learner share of every batch
    reuse = DaggerConfig(fraction=0.5, reuse=[str(folder)])
    assert train_bc(small_config(tmp_path, "second", steps=5, val_every=5, dagger=reuse))
    assert sizes == [reused_steps] * 5
    sizes.clear()
    # with a round: first the reused states alone, then the new round's beside them
    more = DaggerConfig(**{**vars(dagger), "seed": 1200, "reuse": [str(folder)]})
    assert train_bc(small_config(tmp_path, "third", steps=3, val_every=5, dagger=more))
    assert sizes == [reused_steps] * 3 + [2 * reused_steps] * 10
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match=r"dagger.reuse: .*empty holds no DAgger shards"):
        train_bc(
            small_config(tmp_path, "fourth", dagger=DaggerConfig(reuse=[str(tmp_path / "empty")]))
        )


def test_sweep_runs_each_kind_and_receptive_field_and_resumes(tmp_path) -> None:
    """``marl-cover sweep`` trains one model per (kind, K) in ``OUT/<kind>_k<K>``, skips a finished
    run, resumes an interrupted one, and names a bad override before it trains anything."""
    small_dataset(tmp_path / "data")
    out = tmp_path / "sweep"
    overrides = [
        f"dataset={tmp_path / 'data'}",
        "env.map=city",
        "env.city_size=90",
        "env.hops=3",
        "env.max_steps=12",
        "model.hidden=8",
        "batch_size=8",
        "val_every=10",
        "val_fraction=0.25",
        "select_episodes=2",
        "holdout_seeds=[0,2]",
        "logger=csv",
        "progress=false",
    ]

    def sweep(steps: int, *kinds: str):  # noqa: ANN202
        args = [*(f"bc.{item}" for item in overrides), f"bc.steps={steps}"]
        return run_cli("sweep", *args, f"kinds=[{','.join(kinds)}]", "hops=[2,3]", f"out={out}")

    done = sweep(10, "linear", "nonlinear")
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in out.iterdir()) == [
        "linear_k2",
        "linear_k3",
        "nonlinear_k2",
        "nonlinear_k3",
    ]
    for folder in out.iterdir():
        model, info = load_model(folder / "model.pt")
        kind, hops = folder.name.split("_k")
        assert (model.config.kind, model.config.hops, model.config.hidden) == (kind, int(hops), 8)
        assert info["step"] == 10

    (out / "linear_k3" / "model.pt").unlink()  # interrupted after its checkpoint at step 10
    done = sweep(20, "linear")
    assert done.returncode == 0, done.stderr
    assert load_model(out / "linear_k2" / "model.pt")[1]["step"] == 10  # finished: skipped
    assert load_model(out / "linear_k3" / "model.pt")[1]["step"] == 20  # resumed to 20
    assert "linear K=2" not in done.stdout and "linear K=3" in done.stdout

    done = sweep(-1, "linear")
    assert done.returncode == 1 and "steps >= 0" in done.stderr
