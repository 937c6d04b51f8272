"""The shipped models: five named files, each with a card that matches it, golden rewards on
fixed seeds, and the presets that reproduce their recipes."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict

import pytest

import marl_cover

torch = pytest.importorskip("torch")

from marl_cover.agents.cli import options  # noqa: E402
from marl_cover.agents.evaluation.episodes import evaluate  # noqa: E402
from marl_cover.agents.models.checkpoints import load_checkpoint, load_model  # noqa: E402
from marl_cover.agents.models.policy import GNNPolicy  # noqa: E402
from marl_cover.agents.models.shipped import (  # noqa: E402
    SHIPPED,
    SHIPPED_MODELS,
    default_model,
    model_card,
    model_path,
)
from marl_cover.agents.training.mappo import MAPPOConfig  # noqa: E402

#: Rewards of each shipped model (float64, argmax, ego-graphs) on procedural cities of its task,
#: seeds 0..4, 4 robots.
GOLDEN_CITY = {
    "gnn": [94.0, 90.0, 93.0, 95.0, 83.0],
    "gnn_linear": [83.0, 90.0, 86.0, 92.0, 94.0],
    "gnn_mappo": [74.0, 93.0, 78.0, 92.0, 90.0],
    "gnn_exploration": [94.0, 86.0, 85.0, 90.0, 85.0],
    "gnn_mission": [86.0, 83.0, 87.0, 88.0, 75.0],
}


def test_five_models_ship_each_with_its_card() -> None:
    assert (
        sorted(p.stem for p in SHIPPED.glob("*.pt"))
        == sorted(SHIPPED_MODELS)
        == sorted(GOLDEN_CITY)
    )
    assert sorted(p.stem for p in SHIPPED.glob("*.json")) == sorted(SHIPPED_MODELS)
    assert not [p for p in SHIPPED.iterdir() if p.is_dir() and p.name != "__pycache__"]
    assert (default_model("coverage"), default_model("exploration")) == ("gnn", "gnn_exploration")


@pytest.mark.parametrize("name", list(SHIPPED_MODELS))
def test_the_card_describes_its_file(name: str) -> None:
    card = model_card(name)
    path = model_path(name)
    assert card["name"] == name and card["file"] == path.name
    assert card["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert card["weights_sha256"] == load_checkpoint(path)["sha256"]
    model, metadata = load_model(path)
    assert metadata == {"name": name, "card": f"{name}.json"}
    assert card["architecture"] == asdict(model.config)
    assert card["parameters"] == sum(p.numel() for p in model.parameters())
    assert card["task"] == SHIPPED_MODELS[name]
    # the recipe starts from the dataset and ends with the command that made this file
    assert card["recipe"][0]["command"].startswith("marl-cover collect")
    assert all(step["command"].startswith("marl-cover ") for step in card["recipe"])
    assert "this file" in card["recipe"][-1]["makes"]
    test = card["test"]
    assert test["mean"] > 0 and test["sem"] > 0 and test["command"].startswith("marl-cover ")


@pytest.mark.parametrize("name", list(SHIPPED_MODELS))
def test_golden_rewards_of_the_shipped_models(name: str) -> None:
    model, _ = load_model(model_path(name))
    env = marl_cover.parallel_env(hops=model.config.hops, task=SHIPPED_MODELS[name])
    summary = evaluate(env, GNNPolicy(model.double()), range(5))
    assert [r.reward for r in summary.results] == GOLDEN_CITY[name]


@pytest.mark.parametrize("task", ["coverage", "exploration"])
def test_one_pass_plays_as_the_ego_graphs(task: str) -> None:
    model, _ = load_model(model_path(default_model(task)))
    env = marl_cover.parallel_env(hops=model.config.hops, task=task)
    summary = evaluate(env, GNNPolicy(model.double(), centralized=True), range(5))
    assert [r.reward for r in summary.results] == GOLDEN_CITY[default_model(task)]


@pytest.mark.parametrize(
    ("name", "preset"),
    [("gnn_mappo", "mappo_finetune_8000"), ("gnn_exploration", "mappo_finetune_exploration")],
)
def test_the_presets_reproduce_the_recorded_recipes(name: str, preset: str) -> None:
    """The card's last ``train-mappo`` command, read through today's preset, gives the config
    the card records: a changed preset would no longer make the shipped model."""
    card = model_card(name)
    command = next(s["command"] for s in card["recipe"] if "train-mappo" in s["command"])
    _, _, *args = command.split()
    assert args[:2] == ["--config", preset]
    config = options.as_dict(options.load(MAPPOConfig, preset, args[2:]))
    for where in ("backend", "ray"):  # where collection runs, not what it computes
        del config["collector"][where]
    # settings newer than the card (how observations are stored) must be at their defaults
    defaults = asdict(marl_cover.EnvSettings())
    for key in set(config["env"]) - set(card["config"]["env"]):
        assert config["env"].pop(key) == defaults[key], key
    assert config == card["config"]


def test_a_bad_model_name_is_named_with_the_shipped_ones(tmp_path) -> None:
    with pytest.raises(FileNotFoundError, match=r"no model file at gnn_v9 .*'gnn_linear'"):
        model_path("gnn_v9")
    with pytest.raises(KeyError, match="no shipped model 'nope'"):
        model_card("nope")
    with pytest.raises(ValueError, match="no shipped model for task 'flight'"):
        default_model("flight")
    file = tmp_path / "m.pt"
    file.write_bytes(b"")
    assert model_path(file) == file
    assert json.loads((SHIPPED / "gnn.json").read_text())["task"] == "coverage"
