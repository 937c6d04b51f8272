"""The fuzz harness: a short run finds nothing, and a planted bug is found and reproduced."""

from __future__ import annotations

import importlib

import numpy as np
import pytest
from helpers import run_cli

from marl_cover.agents.evaluation.fuzz import INVARIANTS, fuzz


def test_a_short_run_breaks_no_invariant() -> None:
    report = fuzz(100_000, seed=0)
    assert report.agent_steps >= 100_000
    assert report.violations == [], report.violations[:3]
    assert report.refused_inputs > 100
    for setting in (
        "map=city",
        "map=lattice",
        "map=jittered",
        "task=coverage",
        "task=exploration",
        "invalid_action=noop",
        "invalid_action=raise",
        "robots=1",
        "robots=2-9",
        "robots=10-99",
        "robots=100+",
    ):
        assert report.settings[setting] > 5, setting


def _share_freely(robot_node, targets, allow_swaps):  # noqa: ANN001, ANN202
    """A resolver that lets robots share waypoints (the bug to find)."""
    return np.asarray(targets).copy()


def test_a_planted_bug_is_found_and_reproduced(monkeypatch) -> None:
    env_module = importlib.import_module("marl_cover.env")  # marl_cover.env is the function
    monkeypatch.setattr(env_module, "resolve_collisions", _share_freely)
    monkeypatch.setattr(  # the compiled resolver, where numba is installed
        env_module, "resolve_collisions_compiled", lambda c, t, s, _: _share_freely(c, t, s)
    )
    report = fuzz(3000, seed=0, replay_every=0)
    found = {v["invariant"] for v in report.violations}
    assert "no_sharing" in found and found <= set(INVARIANTS)
    first = report.violations[0]
    again = fuzz(1, seed=0, cases=[first["case"]], replay_every=0)
    assert again.violations == [first]


def test_the_command_prints_its_table(tmp_path) -> None:
    out = tmp_path / "fuzz.json"
    done = run_cli("fuzz", "agent_steps=2000", "seed=3", f"out={out}")
    assert done.returncode == 0, done.stderr
    assert "| no_sharing | 0 |" in done.stdout and "agent-steps in" in done.stdout
    import json

    result = json.loads(out.read_text())
    assert result["agent_steps"] >= 2000 and result["violations"] == []
    assert set(result["violations_by_invariant"]) == set(INVARIANTS)


@pytest.mark.parametrize("argument", ["agent_steps=0", "illegal_fraction=2", "cases=[-1]"])
def test_bad_settings_are_named(argument: str) -> None:
    done = run_cli("fuzz", argument)
    assert done.returncode != 0 and argument.split("=")[0] in done.stderr
