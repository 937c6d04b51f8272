"""The models shipped with the library, chosen by name, each with a model card beside it.

=================  ============  ==============================================================
name               task          what it is
=================  ============  ==============================================================
``gnn``            coverage      the default: non-linear GNN, a block per hop, DAgger, averaged
``gnn_linear``     coverage      the paper's linear GNN at width 32, DAgger
``gnn_mappo``      coverage      the behaviour-cloned GNN fine-tuned by MAPPO
``gnn_exploration``  exploration  the default for exploration: DAgger, then MAPPO, averaged
``gnn_mission``    coverage      29 hops, for the quadrotor mission (DAgger, then MAPPO)
=================  ============  ==============================================================

``<name>.pt`` is the network (:func:`marl_cover.agents.models.checkpoints.load_model`);
``<name>.json`` is its card: the commands that made it, its data and seeds, its test figures
and the SHA-256 of the ``.pt``. Every intermediate model of those recipes is one command away
(the card's ``recipe``), not shipped. Needs neither torch nor any other optional package to look up.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from marl_cover.agents.io import read_json
from marl_cover.errors import BadFileError

SHIPPED = Path(__file__).resolve().parent

#: Shipped model name -> the task it was trained for.
SHIPPED_MODELS: dict[str, str] = {
    "gnn": "coverage",
    "gnn_linear": "coverage",
    "gnn_mappo": "coverage",
    "gnn_exploration": "exploration",
    "gnn_mission": "coverage",
}
#: The model ``policy=gnn`` runs when no model is named, by task.
DEFAULT_MODELS: dict[str, str] = {"coverage": "gnn", "exploration": "gnn_exploration"}


def default_model(task: str = "coverage") -> str:
    """The name of the default model of ``task``.

    Raises:
        ValueError: an unknown task, naming the tasks.
    """
    if task not in DEFAULT_MODELS:
        raise ValueError(f"no shipped model for task {task!r}; tasks: {sorted(DEFAULT_MODELS)}")
    return DEFAULT_MODELS[task]


def model_path(name: str | Path) -> Path:
    """The file of a shipped model name, or ``name`` itself when it is a model file.

    Raises:
        FileNotFoundError: ``name`` is neither a shipped name nor a file, naming both the
            shipped names and the path looked at.
    """
    if str(name) in SHIPPED_MODELS:
        return SHIPPED / f"{name}.pt"
    path = Path(name)
    if path.is_file():
        return path
    raise FileNotFoundError(
        f"no model file at {path} and no shipped model of that name; shipped models: "
        f"{sorted(SHIPPED_MODELS)} (docs/models.md: the command that makes any other)"
    )


def model_card(name: str) -> dict[str, Any]:
    """The card of a shipped model (its JSON file, as a dict).

    Raises:
        KeyError: ``name`` is not a shipped model, naming the shipped ones.
        BadFileError: the card is not JSON or not this model's, naming it.
    """
    if name not in SHIPPED_MODELS:
        raise KeyError(f"no shipped model {name!r}; shipped models: {sorted(SHIPPED_MODELS)}")
    card = read_json(SHIPPED / f"{name}.json")
    if not isinstance(card, dict) or card.get("name") != name:
        raise BadFileError(SHIPPED / f"{name}.json", f"not the model card of {name!r}")
    return card
