"""Model files: a network's :class:`~marl_cover.agents.models.gnn.GNNConfig`, its weights and
metadata (command, seed, dataset), written atomically; and weight averages of several files.
"""

from __future__ import annotations

import io
import pickle
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import torch

from marl_cover.agents.io import write_bytes_atomic
from marl_cover.agents.models.gnn import AggregationGNN, GNNConfig


def save_model(
    path: str | Path, model: AggregationGNN, metadata: dict[str, Any], **extra: Any
) -> None:
    """Writes ``model`` with its config and ``metadata`` to ``path`` atomically.

    ``extra`` entries (a training checkpoint's optimiser, sampler, ...) are stored beside them;
    :func:`load_model` ignores them.
    """
    buffer = io.BytesIO()
    record = {"gnn_config": asdict(model.config), "state_dict": model.state_dict()}
    torch.save({**record, "metadata": metadata, **extra}, buffer)
    write_bytes_atomic(path, buffer.getvalue())


def load_model(path: str | Path) -> tuple[AggregationGNN, dict[str, Any]]:
    """The network saved at ``path`` (by :func:`save_model` or a training checkpoint).

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: the file is not a model file, naming it and the missing key.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no model file at {path}")
    try:
        record = torch.load(path, map_location="cpu", weights_only=False)
    except (pickle.UnpicklingError, EOFError, RuntimeError) as error:  # not a torch file
        raise ValueError(f"{path} is not a model file ({type(error).__name__}: {error})") from None
    for key in ("gnn_config", "state_dict"):
        if not isinstance(record, dict) or key not in record:
            raise ValueError(f"{path} is not a model file (no {key!r} entry)")
    model = AggregationGNN(GNNConfig(**record["gnn_config"]))
    model.load_state_dict(record["state_dict"])
    return model.eval(), dict(record.get("metadata", {}))


def average_models(paths: Sequence[str | Path]) -> tuple[AggregationGNN, dict[str, Any]]:
    """The parameter-wise mean of the networks saved at ``paths`` (a "model soup", with
    ``torch.optim.swa_utils.AveragedModel``'s equal-weight running mean).

    Meant for snapshots of one run, or models fine-tuned from one start, whose weights stay
    close; the metadata is the first file's, with ``"average_of"`` listing every file.

    Raises:
        ValueError: fewer than two files, or a file whose network has another config than the
            first's, naming it.
    """
    from torch.optim.swa_utils import AveragedModel

    if len(paths) < 2:
        raise ValueError(f"averaging needs at least two model files, got {len(paths)}")
    models, metadata = _load_alike(paths)
    averaged = AveragedModel(models[0])
    for model in models:
        averaged.update_parameters(model)
    average = averaged.module
    assert isinstance(average, AggregationGNN)
    return average.eval(), {**metadata, "average_of": [str(p) for p in paths]}


def _load_alike(paths: Sequence[str | Path]) -> tuple[list[AggregationGNN], dict[str, Any]]:
    """The networks at ``paths`` and the first one's metadata; a ``ValueError`` names a file
    whose network has another config than the first's."""
    (first, metadata), *others = [load_model(path) for path in paths]
    for path, (model, _) in zip(paths[1:], others, strict=True):
        if model.config != first.config:
            raise ValueError(
                f"{path} holds a {model.config} network, not the {first.config} of {paths[0]}"
            )
    return [first, *(model for model, _ in others)], metadata
