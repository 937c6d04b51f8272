"""Static checks of the code, so that CI holds them and not only ``make lint``.

- mypy (``[tool.mypy]`` in pyproject.toml, run by ``tests/typecheck.py`` on the installed
  layout): ``marl_cover``, which ships ``py.typed``, so the annotations users' type checkers
  read are the ones the code obeys, ``marl_cover.agents`` and ``scripts``.
- ruff (``[tool.ruff]``): the lint rules, docstrings on every public module, class, method and
  function of the packages, and the formatting.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CODE = ["marl_cover", "agents", "configs", "scripts", "tests"]


def test_code_type_checks() -> None:
    pytest.importorskip("mypy.api")
    from typecheck import run_mypy

    report, status = run_mypy()
    assert status == 0, report
    assert "Success: no issues found" in report


@pytest.mark.parametrize("command", [["check"], ["format", "--check"]])
def test_code_passes_ruff(command: list[str]) -> None:
    pytest.importorskip("ruff")
    result = subprocess.run(
        [sys.executable, "-m", "ruff", *command, *CODE],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stdout + result.stderr


def test_no_module_is_a_wall_of_code() -> None:
    """Small modules with one job each: none of the packages' modules exceeds 600 lines."""
    long = {
        str(path.relative_to(ROOT)): count
        for folder in ("marl_cover", "agents", "scripts")
        for path in (ROOT / folder).rglob("*.py")
        if (count := len(path.read_text().splitlines())) > 600
    }
    assert not long, long
