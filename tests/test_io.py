"""Files shared by the commands: atomic writes, content digests, setup-checked resume."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from marl_cover.agents.io import file_sha256, read_result, write_bytes_atomic, write_text_atomic


def test_atomic_writes_leave_no_temporary_file(tmp_path: Path) -> None:
    path = write_text_atomic(tmp_path / "deep" / "a.json", "{}")
    assert path.read_text() == "{}"
    write_bytes_atomic(path, b"[1]")
    assert path.read_bytes() == b"[1]"
    assert sorted(p.name for p in path.parent.iterdir()) == ["a.json"]


def test_file_sha256_names_the_content(tmp_path: Path) -> None:
    a, b = tmp_path / "a.pt", tmp_path / "b.pt"
    a.write_bytes(b"weights")
    b.write_bytes(b"weights")
    assert file_sha256(a) == file_sha256(b)
    assert file_sha256(a) == "9a129038d9a00aed0cf6a7ea059ca50a813449061ab87848cf1a13eafdf33b2c"
    b.write_bytes(b"other weights")
    assert file_sha256(a) != file_sha256(b)


def test_read_result_checks_the_setup(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    setup = {"method": "gnn", "robots": 10, "range": (3.0, 8.0)}
    path = tmp_path / "gnn_R10.json"
    path.write_text(json.dumps({"mean": 1.5, "setup": setup}))
    assert read_result(path, setup)["mean"] == 1.5  # a tuple reads back as a list: same setup
    with pytest.raises(ValueError, match=r"gnn_R10.json: made under another setup .*\['robots'\]"):
        read_result(path, {**setup, "robots": 20})
    with pytest.raises(ValueError, match=r"differs in \['model_sha256'\]"):
        read_result(path, {**setup, "model_sha256": "abc"})
    old = tmp_path / "old.json"
    old.write_text(json.dumps({"mean": 2.0}))
    assert read_result(old, setup)["mean"] == 2.0
    assert "old.json does not record its setup" in capsys.readouterr().out
