"""The scripts' helpers: ``key=value`` values, argparse types, atomic writes, setup-checked
resume."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from agents.cli import (
    file_sha256,
    non_negative_int,
    parse_value,
    positive_float,
    positive_int,
    read_result,
    write_bytes_atomic,
    write_text_atomic,
)


def test_parse_value() -> None:
    assert parse_value("true") is True and parse_value("False") is False
    assert parse_value("null") is None and parse_value("None") is None
    assert parse_value("3") == 3 and isinstance(parse_value("3"), int)
    assert parse_value("1e-4") == 1e-4
    assert parse_value("[greedy,gnn]") == ["greedy", "gnn"]
    assert parse_value("[1, 2.5]") == [1, 2.5] and parse_value("[]") == []
    assert parse_value("outputs/run") == "outputs/run"


def test_argparse_types_name_the_expectation() -> None:
    assert positive_int("3") == 3 and non_negative_int("0") == 0 and positive_float("0.5") == 0.5
    for parse, text, expected in [
        (positive_int, "0", "an integer >= 1, got '0'"),
        (positive_int, "2.5", "an integer >= 1, got '2.5'"),
        (non_negative_int, "-1", "an integer >= 0, got '-1'"),
        (positive_float, "0", "a number > 0, got '0'"),
        (positive_float, "inf", "a number > 0, got 'inf'"),
        (positive_float, "soon", "a number > 0, got 'soon'"),
    ]:
        with pytest.raises(argparse.ArgumentTypeError, match=f"expected {expected}"):
            parse(text)


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
    with pytest.raises(
        ValueError, match=r"gnn_R10.json was made under another setup .*\['robots'\]"
    ):
        read_result(path, {**setup, "robots": 20})
    with pytest.raises(ValueError, match=r"differs in \['model_sha256'\]"):
        read_result(path, {**setup, "model_sha256": "abc"})
    old = tmp_path / "old.json"
    old.write_text(json.dumps({"mean": 2.0}))
    assert read_result(old, setup)["mean"] == 2.0
    assert "old.json does not record its setup" in capsys.readouterr().out
