"""Model files: read with ``weights_only=True``, checked by their digest, refused by name.

Every bad file gives :class:`marl_cover.errors.BadFileError` naming the file; no bit flip
loads a network that differs from the one saved.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from marl_cover.agents.models.checkpoints import (  # noqa: E402
    MODEL_FORMAT,
    load_checkpoint,
    load_model,
    save_model,
    weights_sha256,
)
from marl_cover.agents.models.gnn import AggregationGNN, GNNConfig  # noqa: E402
from marl_cover.agents.models.shipped import model_path  # noqa: E402
from marl_cover.errors import BadFileError  # noqa: E402


def small_model() -> AggregationGNN:
    torch.manual_seed(0)
    return AggregationGNN(GNNConfig(kind="nonlinear", hops=2, hidden=4))


def write_record(path: Path, record: dict) -> None:
    """A file as ``save_model`` would write ``record``, the digest recomputed (a well-formed
    file whose contents are wrong in another way)."""
    record["sha256"] = weights_sha256(record["model_json"], record["state_dict"])
    torch.save(record, path)


def saved_record(tmp_path: Path) -> dict:
    save_model(tmp_path / "m.pt", small_model(), {"seed": 1})
    return torch.load(tmp_path / "m.pt", weights_only=True)


def test_no_single_byte_flip_loads_a_changed_network(tmp_path) -> None:
    original = small_model()
    save_model(tmp_path / "m.pt", original, {"seed": 1})
    data = (tmp_path / "m.pt").read_bytes()
    rng = np.random.default_rng(0)
    positions = rng.choice(len(data), size=150, replace=False)
    refused = 0
    for position in positions:
        flipped = bytearray(data)
        flipped[position] ^= 1 << int(rng.integers(8))
        path = tmp_path / f"flip_{position}.pt"
        path.write_bytes(bytes(flipped))
        try:
            model, metadata = load_model(path)
        except BadFileError as error:
            assert error.path == path and str(path) in str(error)
            refused += 1
            continue
        # a flip the reader never looks at (zip headers, padding): the network is intact
        assert model.config == original.config and metadata == {"seed": 1}
        for name, tensor in original.state_dict().items():
            assert torch.equal(model.state_dict()[name], tensor), (position, name)
    assert refused >= 50  # the rest fell on zip padding and headers the reader skips


def test_all_nan_weights_are_refused(tmp_path) -> None:
    model = small_model()
    with torch.no_grad():
        for parameter in model.parameters():
            parameter.fill_(float("nan"))
    save_model(tmp_path / "nan.pt", model, {})
    with pytest.raises(BadFileError, match=r"nan.pt: weight '.*' holds \d+ non-finite values"):
        load_model(tmp_path / "nan.pt")


def test_a_wrong_shape_is_named(tmp_path) -> None:
    record = saved_record(tmp_path)
    name = next(iter(record["state_dict"]))
    record["state_dict"][name] = torch.zeros(3, 3, 3)
    write_record(tmp_path / "shape.pt", record)
    with pytest.raises(BadFileError, match=r"shape.pt: its weights do not fit its network .*size"):
        load_model(tmp_path / "shape.pt")


def test_an_unknown_config_key_is_named(tmp_path) -> None:
    record = saved_record(tmp_path)
    config = json.loads(record["model_json"])
    config["gnn_config"]["dropout"] = 0.5
    record["model_json"] = json.dumps(config)
    write_record(tmp_path / "key.pt", record)
    with pytest.raises(
        BadFileError, match=r"key.pt: its network config is not a GNNConfig .*dropout"
    ):
        load_model(tmp_path / "key.pt")


def test_a_digest_mismatch_names_expected_and_found(tmp_path) -> None:
    record = saved_record(tmp_path)
    expected = record["sha256"]
    record["state_dict"][next(iter(record["state_dict"]))] += 1e-3
    torch.save(record, tmp_path / "edited.pt")  # weights changed, digest kept
    found = weights_sha256(record["model_json"], record["state_dict"])
    with pytest.raises(
        BadFileError, match=rf"edited.pt: weights SHA-256 is {found}, the file records {expected}"
    ):
        load_model(tmp_path / "edited.pt")


def test_a_card_beside_the_file_is_checked(tmp_path) -> None:
    for suffix in (".pt", ".json"):
        shutil.copy(model_path("gnn_linear").with_suffix(suffix), tmp_path / f"m{suffix}")
    load_model(tmp_path / "m.pt")
    card = json.loads((tmp_path / "m.json").read_text())
    found, card["weights_sha256"] = card["weights_sha256"], "0" * 64
    (tmp_path / "m.json").write_text(json.dumps(card))
    with pytest.raises(
        BadFileError, match=rf"m.pt: weights SHA-256 is {found}, its card m.json records 0{{64}}"
    ):
        load_model(tmp_path / "m.pt")


class _Payload:
    """Pickled code a reader with ``weights_only=False`` would run."""

    marker: Path

    def __reduce__(self):  # noqa: ANN204
        return (Path.touch, (self.marker,))


def test_pickled_code_is_never_run(tmp_path) -> None:
    payload = _Payload()
    payload.marker = tmp_path / "ran"
    record = saved_record(tmp_path)
    record["optimizer"] = payload
    torch.save(record, tmp_path / "evil.pt")
    with pytest.raises(BadFileError, match="evil.pt: not a readable model file"):
        load_model(tmp_path / "evil.pt")
    assert not payload.marker.exists()


def test_files_without_a_digest_need_verify_false(tmp_path) -> None:
    model = small_model()
    legacy = {"gnn_config": {"kind": "nonlinear", "hops": 2, "hidden": 4}}
    torch.save(
        {**legacy, "state_dict": model.state_dict(), "metadata": {"seed": 3}}, tmp_path / "old.pt"
    )
    with pytest.raises(BadFileError, match=rf"old.pt: not a {MODEL_FORMAT} file .*verify=False"):
        load_model(tmp_path / "old.pt")
    loaded, metadata = load_model(tmp_path / "old.pt", verify=False)
    assert metadata == {"seed": 3} and loaded.config == model.config
    save_model(tmp_path / "new.pt", loaded, metadata)
    assert load_checkpoint(tmp_path / "new.pt")["format"] == MODEL_FORMAT


def test_extra_entries_cannot_replace_the_model(tmp_path) -> None:
    with pytest.raises(ValueError, match=r"extra entries \['sha256'\]"):
        save_model(tmp_path / "m.pt", small_model(), {}, sha256="x")
