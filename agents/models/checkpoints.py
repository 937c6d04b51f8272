"""Model files: a network's weights (a plain state dict) and its
:class:`~marl_cover.agents.models.gnn.GNNConfig` and metadata as JSON text, with the SHA-256 of
both, written atomically and read with ``torch.load(weights_only=True)`` (no pickled code runs);
and weight averages of several files.

A file is a ``torch.save`` of the dict::

    {"format": "marl-cover-model/2",
     "model_json": '{"gnn_config": {...}, "metadata": {...}}',
     "state_dict": {name: tensor, ...},
     "sha256": "...",                                        # of the config text and weights
     ...}                                                    # a training checkpoint's state

Reading one checks the digest (and the ``weights_sha256`` of a model card beside the file,
``<stem>.json``, where there is one), that every weight is finite, and that the config and the
weights fit the network; anything else is a :class:`~marl_cover.errors.BadFileError` naming the
file.
"""

from __future__ import annotations

import hashlib
import io
import json
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import torch

from marl_cover.agents.io import read_json, write_bytes_atomic
from marl_cover.agents.models.gnn import AggregationGNN, GNNConfig
from marl_cover.errors import BadFileError, MissingFileError

#: The ``format`` entry of the model files this version writes and reads.
MODEL_FORMAT = "marl-cover-model/2"


def weights_sha256(config_text: str, state_dict: Mapping[str, torch.Tensor]) -> str:
    """The SHA-256 of a model's config text and weights (names, dtypes, shapes and bytes, in
    name order): what a model file and its card record."""
    digest = hashlib.sha256(config_text.encode("utf-8"))
    for name in sorted(state_dict):
        tensor = state_dict[name].detach().cpu().contiguous()
        digest.update(f"\n{name}:{tensor.dtype}:{tuple(tensor.shape)}\n".encode())
        digest.update(tensor.view(-1).view(torch.uint8).numpy().tobytes())
    return digest.hexdigest()


def save_model(
    path: str | Path, model: AggregationGNN, metadata: dict[str, Any], **extra: Any
) -> None:
    """Writes ``model`` with its config and ``metadata`` (JSON-able) to ``path`` atomically.

    ``extra`` entries (a training checkpoint's optimiser, sampler, ...: tensors, numbers,
    strings and containers of them) are stored beside them; :func:`load_model` ignores them.
    """
    config_text = json.dumps(
        {"gnn_config": asdict(model.config), "metadata": metadata}, sort_keys=True, default=str
    )
    state_dict = {k: v.detach().cpu() for k, v in model.state_dict().items()}
    record = {
        "format": MODEL_FORMAT,
        "model_json": config_text,
        "state_dict": state_dict,
        "sha256": weights_sha256(config_text, state_dict),
    }
    clash = sorted(set(record) & set(extra))
    if clash:
        raise ValueError(f"save_model: extra entries {clash} would replace the model's own")
    buffer = io.BytesIO()
    torch.save({**record, **extra}, buffer)
    write_bytes_atomic(path, buffer.getvalue())


def load_checkpoint(
    path: str | Path, map_location: str | torch.device = "cpu", verify: bool = True
) -> dict[str, Any]:
    """The whole record of a model file, checked: its entries as saved, plus ``gnn_config``
    and ``metadata`` read from its config text.

    Args:
        path: The file.
        map_location: Where its tensors go.
        verify: Check the digest. ``False`` also reads the files of marl-cover 1.0, which
            hold none (``save_model`` re-saves one with its digest).

    Raises:
        MissingFileError: no file at ``path``.
        BadFileError: naming the file: not a model file, a digest that does not match (the
            expected and the found), a non-finite weight, or unreadable config text.
    """
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(path, "no model file here")
    try:
        record = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as error:  # noqa: BLE001 (zip, pickle and torch errors alike)
        raise BadFileError(path, f"not a readable model file ({_reason(error)})") from None
    if not isinstance(record, dict) or not isinstance(record.get("state_dict"), dict):
        raise BadFileError(path, "not a model file (no 'state_dict' entry)")
    if record.get("format") == MODEL_FORMAT:
        _check_digest(path, record)
        record.update(_parse_config(path, record.get("model_json")))
    elif not verify and isinstance(record.get("gnn_config"), dict):
        record.setdefault("metadata", {})  # a 1.0 file: config as a dict, no digest
    else:
        raise BadFileError(
            path,
            f"not a {MODEL_FORMAT} file (format {record.get('format')!r}); a file without a "
            "digest is read by load_model(path, verify=False) and re-saved by save_model",
        )
    for name, tensor in record["state_dict"].items():
        if not isinstance(tensor, torch.Tensor):
            raise BadFileError(path, f"weight {name!r} is not a tensor")
        if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
            bad = int((~torch.isfinite(tensor)).sum())
            raise BadFileError(path, f"weight {name!r} holds {bad} non-finite values")
    return record


def load_model(path: str | Path, verify: bool = True) -> tuple[AggregationGNN, dict[str, Any]]:
    """The network saved at ``path`` (by :func:`save_model` or a training checkpoint), checked
    as :func:`load_checkpoint` says.

    Raises:
        MissingFileError: no file at ``path``.
        BadFileError: the file fails a check, or its config or weights do not make a network
            (an unknown config key, a wrong tensor shape), naming the file.
    """
    record = load_checkpoint(path, verify=verify)
    try:
        model = AggregationGNN(GNNConfig(**record["gnn_config"]))
    except (TypeError, ValueError) as error:
        raise BadFileError(path, f"its network config is not a GNNConfig ({error})") from None
    try:
        model.load_state_dict(record["state_dict"])
    except RuntimeError as error:
        problem = " ".join(str(error).split())
        raise BadFileError(path, f"its weights do not fit its network ({problem})") from None
    metadata = record["metadata"]
    return model.eval(), dict(metadata) if isinstance(metadata, dict) else {}


def _reason(error: Exception) -> str:
    """A load error in one line; for pickled code, only what ``weights_only`` refused."""
    text = str(error)
    refused = [line for line in text.splitlines() if "WeightsUnpickler error:" in line]
    if refused:
        text = refused[0].strip() + " (weights_only=True runs no pickled code)"
    return f"{type(error).__name__}: {' '.join(text.split())}"


def _check_digest(path: Path, record: dict[str, Any]) -> None:
    """The file's digest, and a card's beside it, against the config text and weights."""
    config_text = record.get("model_json")
    if not isinstance(config_text, str):
        raise BadFileError(path, "not a model file (no config text)")
    found = weights_sha256(config_text, record["state_dict"])
    if found != record.get("sha256"):
        raise BadFileError(
            path, f"weights SHA-256 is {found}, the file records {record.get('sha256')}"
        )
    card_path = path.with_suffix(".json")
    if card_path.is_file():
        card = read_json(card_path)
        expected = card.get("weights_sha256") if isinstance(card, dict) else None
        if expected is not None and expected != found:
            raise BadFileError(
                path, f"weights SHA-256 is {found}, its card {card_path.name} records {expected}"
            )


def _parse_config(path: Path, config_text: Any) -> dict[str, Any]:
    """``gnn_config`` and ``metadata`` from a file's config text."""
    try:
        config = json.loads(config_text)
        return {"gnn_config": dict(config["gnn_config"]), "metadata": config.get("metadata", {})}
    except (TypeError, ValueError, KeyError) as error:
        raise BadFileError(path, f"its config text is not a model config ({error})") from None


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
