"""The code type-checks (``[tool.mypy]`` in pyproject.toml: ``marl_cover``, which ships
``py.typed``, so the annotations users' type checkers read are the ones the code obeys,
``agents`` and ``scripts``)."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_code_type_checks(monkeypatch: pytest.MonkeyPatch) -> None:
    api = pytest.importorskip("mypy.api")
    monkeypatch.chdir(ROOT)  # the pyproject's [tool.mypy] section and its cache
    stdout, stderr, status = api.run(["--config-file", "pyproject.toml"])
    assert status == 0, stdout + stderr
    assert "Success: no issues found" in stdout
