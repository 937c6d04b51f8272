"""The shipped models (coverage, exploration): their cards, and golden rewards on fixed seeds."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

import marl_cover

torch = pytest.importorskip("torch")

from agents.cli import file_sha256  # noqa: E402
from agents.evaluation import evaluate  # noqa: E402
from agents.models import AggregationGNN  # noqa: E402
from agents.models.policy import GNNPolicy, load_model  # noqa: E402
from agents.models.shipped import SHIPPED, shipped_model_path  # noqa: E402

#: Rewards of each shipped model (float64, argmax) on procedural cities, seeds 0..4, 4 robots.
GOLDEN_CITY = {
    "coverage": [94.0, 90.0, 93.0, 95.0, 83.0],
    "exploration": [94.0, 86.0, 85.0, 90.0, 85.0],
}


def shipped_beside(folder: str) -> tuple[AggregationGNN, dict, dict]:
    """The model, its metadata and its card in ``shipped/<folder>/coverage_gnn.*``."""
    path = SHIPPED / folder / "coverage_gnn.pt"
    model, metadata = load_model(path)
    return model, metadata, json.loads(path.with_suffix(".json").read_text())


def city_rewards(model: AggregationGNN) -> list[float]:
    """Rewards of ``model`` (float64, argmax, ego-graphs) on procedural cities, seeds 0..4."""
    env = marl_cover.parallel_env(hops=model.config.hops)
    return [r.reward for r in evaluate(env, GNNPolicy(model.double()), range(5)).results]


@pytest.mark.parametrize("task", list(GOLDEN_CITY))
def test_the_shipped_model_has_a_card_that_names_its_origin(task: str) -> None:
    model, metadata = load_model(shipped_model_path(task))
    card = json.loads((SHIPPED / f"{task}_gnn.json").read_text())
    for key in ("command", "seed", "dataset", "config", "scores"):
        assert key in card, key
    shape = card["config"]["model"]
    shape = shape.get("actor", shape)  # a MAPPO run's config holds the actor and the critic
    assert shape["hops"] == model.config.hops
    assert shape["kind"] == model.config.kind
    assert card["config"]["env"].get("task", "coverage") == task
    origin = metadata.get("init", metadata)  # a fine-tuned model names the one it started from
    assert origin["dataset"].endswith("coverage_expert")
    if "init" in metadata:  # and that model ships beside it, with its own card
        start, _ = load_model(SHIPPED.parents[2] / origin["path"])  # a repository path
        assert start.config == model.config
        assert json.loads((SHIPPED / "bc" / f"{task}_gnn.json").read_text())["dataset"]
    with pytest.raises(FileNotFoundError, match="exploration"):
        shipped_model_path("exploration_v9")


@pytest.mark.parametrize("task", list(GOLDEN_CITY))
@pytest.mark.parametrize("centralized", [False, True])
def test_golden_rewards_of_the_shipped_model(task: str, centralized: bool) -> None:
    model, _ = load_model(shipped_model_path(task))
    env = marl_cover.parallel_env(hops=model.config.hops, task=task)
    summary = evaluate(env, GNNPolicy(model.double(), centralized=centralized), range(5))
    assert [r.reward for r in summary.results] == GOLDEN_CITY[task]


def test_the_dagger_model_ships_with_its_card_and_golden_rewards() -> None:
    """``dagger/coverage_gnn.pt``: the best model on the paper's windows, beside the default."""
    model, metadata, card = shipped_beside("dagger")
    assert card["config"]["init"] == "agents/models/shipped/bc/coverage_gnn.pt"
    start, _ = load_model(SHIPPED.parents[2] / card["config"]["init"])
    assert start.config == model.config
    dagger = card["config"]["dagger"]
    assert (dagger["expert_mode"], dagger["expert_horizon"], dagger["expert_clock"]) == (
        "receding",
        19,
        False,
    )
    assert metadata["step"] == 7000 and metadata["dataset"].endswith("coverage_expert")
    assert city_rewards(model) == [86.0, 97.0, 86.0, 91.0, 88.0]


def test_the_per_hop_dagger_model_grows_from_the_dagger_model() -> None:
    """``dagger_per_hop/coverage_gnn.pt``: a block per hop, started from ``dagger/``'s block."""
    model, metadata, card = shipped_beside("dagger_per_hop")
    assert model.config.per_hop and card["config"]["model"]["per_hop"]
    assert card["config"]["init"] == "agents/models/shipped/dagger/coverage_gnn.pt"
    start, _ = load_model(SHIPPED.parents[2] / card["config"]["init"])
    assert start.per_hop_copy().config == model.config
    assert metadata["step"] == 14000 and metadata["dataset"].endswith("coverage_expert")
    assert city_rewards(model) == [87.0, 91.0, 85.0, 94.0, 78.0]


def test_the_exploration_model_fine_tunes_the_averaged_per_hop_model_by_mappo() -> None:
    """``exploration_gnn.pt`` (since session 30): the mean of nine MAPPO snapshots of the
    session-18 default, which ships in ``swa_per_hop/`` (the weight average of the per-hop
    coverage model's snapshots trained on exploration states); the snapshot that one replaced
    ships in ``dagger_per_hop/`` and the MAPPO fine-tune before it in ``mappo/``, each with its
    card."""
    model, metadata = load_model(shipped_model_path("exploration"))
    card = json.loads((SHIPPED / "exploration_gnn.json").read_text())
    start_path = SHIPPED / "swa_per_hop" / "exploration_gnn.pt"
    start, start_metadata = load_model(start_path)
    assert model.config == start.config and model.config.per_hop
    assert metadata["init"]["path"] == "agents/models/shipped/swa_per_hop/exploration_gnn.pt"
    assert card["init_sha256"] == file_sha256(start_path)
    assert card["config"]["env"]["task"] == "exploration" and card["config"]["algorithm"] == "mappo"
    assert card["config"]["model"]["temperature"] == 0.25
    steps = [f"step_{s:06d}.pt" for s in range(20, 65, 5)]
    assert [path.rsplit("/", 1)[1] for path in metadata["average_of"]] == steps
    assert metadata["selection"]["chosen"] == "steps 20..60 (9)"
    # the start: the session-18 weight average
    start_card = json.loads((SHIPPED / "swa_per_hop" / "exploration_gnn.json").read_text())
    assert start_card["config"]["init"] == "agents/models/shipped/dagger_per_hop/coverage_gnn.pt"
    assert start_card["init_sha256"] == file_sha256(SHIPPED / "dagger_per_hop" / "coverage_gnn.pt")
    steps = [f"step_{s:06d}.pt" for s in range(8000, 17000, 1000)]
    assert [path.rsplit("/", 1)[1] for path in start_metadata["average_of"]] == steps
    assert start_metadata["dataset"].endswith("coverage_expert")
    env = marl_cover.parallel_env(hops=19, task="exploration")
    rewards = [r.reward for r in evaluate(env, GNNPolicy(start.double()), range(5)).results]
    assert rewards == [95.0, 87.0, 87.0, 89.0, 86.0]
    snapshot, snapshot_metadata = load_model(SHIPPED / "dagger_per_hop" / "exploration_gnn.pt")
    assert snapshot.config == model.config and snapshot_metadata["step"] == 8000
    assert "average_of" not in snapshot_metadata
    rewards = [r.reward for r in evaluate(env, GNNPolicy(snapshot.double()), range(5)).results]
    assert rewards == [80.0, 86.0, 72.0, 92.0, 92.0]
    previous, previous_metadata = load_model(SHIPPED / "mappo" / "exploration_gnn.pt")
    assert not previous.config.per_hop and previous_metadata["init"]["dataset"]
    assert "mappo" in json.loads((SHIPPED / "mappo" / "exploration_gnn.json").read_text())["model"]


def test_the_linear_model_ships_with_its_card_and_golden_rewards() -> None:
    """``linear/coverage_gnn.pt``: the best linear model (width 32, BC + DAgger)."""
    model, metadata, card = shipped_beside("linear")
    assert (model.config.kind, model.config.hidden, model.config.hops) == ("linear", 32, 19)
    assert card["config"]["model"]["hidden"] == 32 and card["config"]["dagger"]["rounds"] == 5
    assert metadata["step"] == 10000 and metadata["dataset"].endswith("coverage_expert")
    assert city_rewards(model) == [83.0, 90.0, 86.0, 92.0, 94.0]


def test_the_coverage_model_averages_a_second_run_of_the_per_hop_recipe() -> None:
    """``coverage_gnn.pt`` (since session 20): the mean of the last five snapshots of a second run
    of the per-hop recipe (its own roll-out seeds), the window chosen by ``select_average.py``."""
    model, metadata = load_model(shipped_model_path("coverage"))
    card = json.loads((SHIPPED / "coverage_gnn.json").read_text())
    per_hop, _, per_hop_card = shipped_beside("dagger_per_hop")
    assert model.config == per_hop.config and model.config.per_hop
    assert card["config"]["init"] == per_hop_card["config"]["init"]
    assert card["init_sha256"] == file_sha256(SHIPPED / "dagger" / "coverage_gnn.pt")
    recipe = ("rounds", "episodes", "beta", "steps", "fraction", "expert_mode", "expert_horizon")
    assert {k: card["config"]["dagger"][k] for k in recipe} == {
        k: per_hop_card["config"]["dagger"][k] for k in recipe
    }
    assert card["config"]["dagger"]["seed"] != per_hop_card["config"]["dagger"]["seed"]
    steps = [f"step_{s:06d}.pt" for s in range(12000, 17000, 1000)]
    assert [path.rsplit("/", 1)[1] for path in metadata["average_of"]] == steps
    assert metadata["selection"]["chosen"] == "steps 12000..16000 (5)"


def test_the_29_hop_model_is_grown_from_the_mappo_fine_tune() -> None:
    """``mission/coverage_gnn.pt`` (the mission's model in sessions 25-31):
    ``mappo/coverage_gnn.pt`` (the BC model fine-tuned by MAPPO, the mission's model before)
    grown to 29 hops and trained by DAgger on the mission's discrete stand-in."""
    model, metadata, card = shipped_beside("mission")
    mappo, _, mappo_card = shipped_beside("mappo")
    assert model.config == replace(mappo.config, hops=29)
    assert card["config"]["init"] == "agents/models/shipped/mappo/coverage_gnn.pt"
    assert card["init_sha256"] == file_sha256(SHIPPED / "mappo" / "coverage_gnn.pt")
    dagger = card["config"]["dagger"]
    assert (dagger["expert_mode"], dagger["expert_horizon"], dagger["expert_clock"]) == (
        "receding",
        29,
        False,
    )
    assert dagger["env"]["map"] == "paper_full" and dagger["env"]["num_robots"] == 10
    assert metadata["dataset"].endswith("coverage_expert")
    assert mappo_card["init"]["path"] == "agents/models/shipped/bc/coverage_gnn.pt"
    assert city_rewards(mappo) == [80.0, 86.0, 88.0, 96.0, 81.0]
    assert city_rewards(model) == [89.0, 87.0, 88.0, 82.0, 86.0]


def test_the_mission_flies_the_29_hop_model_fine_tuned_by_mappo_on_the_stand_in() -> None:
    """``mission_mappo/coverage_gnn.pt`` (since session 32): ``mission/coverage_gnn.pt`` fine-tuned
    by MAPPO on the mission's discrete stand-in; the mission's model by default and in
    ``mission.yaml``."""
    from agents.configuration import load
    from agents.mission import MissionConfig, mission_model_path

    model, metadata, card = shipped_beside("mission_mappo")
    assert mission_model_path() == SHIPPED / "mission_mappo" / "coverage_gnn.pt"
    config = load(MissionConfig, SHIPPED.parents[2] / "configs" / "mission.yaml", [])
    assert SHIPPED.parents[2] / config.checkpoint == mission_model_path()
    assert MissionConfig().setup("gnn")["model_sha256"] == file_sha256(mission_model_path())
    assert config.observation_hops() == 29  # the mission's ego-graphs span its field
    start, start_metadata, _ = shipped_beside("mission")
    assert model.config == start.config
    assert metadata["algorithm"] == "mappo"
    assert metadata["init"]["path"] == "agents/models/shipped/mission/coverage_gnn.pt"
    assert metadata["init"]["step"] == start_metadata["step"]
    assert card["init_sha256"] == file_sha256(SHIPPED / "mission" / "coverage_gnn.pt")
    env = card["config"]["env"]
    assert (env["map"], env["num_robots"], env["hops"], env["max_steps"]) == (
        "paper_full",
        10,
        29,
        131,
    )
    assert card["config"]["init"] == "agents/models/shipped/mission/coverage_gnn.pt"
    assert city_rewards(model) == [86.0, 83.0, 87.0, 88.0, 75.0]


def test_the_8000_step_fine_tune_is_the_bc_model_trained_by_the_recipe_of_issue_6() -> None:
    """``mappo_8000/coverage_gnn.pt`` (session 45): the BC model fine-tuned by MAPPO with 8000
    env steps a gradient step, its iterate 230 (read as fixed beforehand, docs/results/mappo.md)."""
    model, metadata, card = shipped_beside("mappo_8000")
    bc, _, _ = shipped_beside("bc")
    assert model.config == bc.config
    assert metadata["algorithm"] == "mappo" and metadata["iteration"] == 230
    assert metadata["init"]["path"] == "agents/models/shipped/bc/coverage_gnn.pt"
    assert card["init"]["sha256"] == file_sha256(SHIPPED / "bc" / "coverage_gnn.pt")
    config = card["config"]
    assert config["init"] == "agents/models/shipped/bc/coverage_gnn.pt"
    assert (config["collector"]["frames_per_batch"], config["collector"]["n_iters"]) == (8000, 230)
    assert (config["optim"]["lr"], config["model"]["temperature"]) == (0.0003, 0.25)
    rewards = city_rewards(model)
    assert rewards == card["scores"]["cities_seeds_0_4_float64"] == [74.0, 93.0, 78.0, 92.0, 90.0]


def test_the_8000_step_preset_is_the_recipe_of_the_shipped_fine_tune() -> None:
    """``configs/mappo_finetune_8000.yaml`` with the run's folder and quiet progress gives the
    settings recorded in ``mappo_8000/coverage_gnn.json``."""
    from agents import configuration
    from agents.training.mappo import MAPPOConfig

    card = json.loads((SHIPPED / "mappo_8000" / "coverage_gnn.json").read_text())
    preset = SHIPPED.parents[2] / "configs" / "mappo_finetune_8000.yaml"
    overrides = ["out=outputs/runs/seed0", "progress=false"]
    recorded = configuration.build(MAPPOConfig, card["config"], "the card's config")
    assert configuration.load(MAPPOConfig, preset, overrides) == recorded


def test_the_exploration_8000_step_preset_is_the_coverage_recipe_from_the_shipped_model() -> None:
    """``configs/mappo_finetune_exploration_8000.yaml`` is the shipped exploration model's own
    MAPPO config (its card) started from that model, with the 8000-step coverage preset's
    collector and optimizer settings and nothing else changed."""
    from agents import configuration
    from agents.training.mappo import MAPPOConfig

    configs = SHIPPED.parents[2] / "configs"
    card = json.loads((SHIPPED / "exploration_gnn.json").read_text())
    recorded = configuration.build(MAPPOConfig, card["config"], "the card's config")
    preset_path = configs / "mappo_finetune_exploration_8000.yaml"
    preset = configuration.load(MAPPOConfig, preset_path, [f"out={recorded.out}", "progress=false"])
    coverage = configuration.load(MAPPOConfig, configs / "mappo_finetune_8000.yaml", [])
    assert preset.env == {**coverage.env, "task": "exploration"}
    assert preset == replace(
        recorded,
        init="agents/models/shipped/exploration_gnn.pt",
        collector=coverage.collector,
        optim=coverage.optim,
    )
    assert (preset.loss, preset.model) == (coverage.loss, coverage.model)
