"""Choosing a weight average of a run's snapshots (marl_cover.agents.training.averaging, marl-cover
average)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
import torch
from helpers import run_cli

import marl_cover
from marl_cover.agents.evaluation.episodes import evaluate
from marl_cover.agents.models import AggregationGNN, GNNConfig
from marl_cover.agents.models.checkpoints import average_models, load_model, save_model
from marl_cover.agents.models.policy import GNNPolicy
from marl_cover.agents.training import averaging
from marl_cover.agents.training.averaging import select_window, snapshot_files, trailing_windows

ROOT = Path(__file__).resolve().parent.parent
ENV = {"map": "city", "task": "coverage", "max_steps": 6}


@pytest.fixture(autouse=True)
def _one_thread() -> None:
    torch.set_num_threads(1)


def make_run(folder: Path, steps=(1000, 2000, 3000)) -> list[Path]:
    """A run folder with snapshots of small random networks (K = 2)."""
    (folder / "steps").mkdir(parents=True)
    files = []
    for step in steps:
        torch.manual_seed(step)
        path = folder / "steps" / f"step_{step:06d}.pt"
        save_model(path, AggregationGNN(GNNConfig(hops=2, hidden=8)), {"step": step})
        files.append(path)
    (folder / "steps" / "notes.txt").write_text("not a snapshot")
    return files


def test_snapshots_are_found_by_step_and_windows_trail(tmp_path) -> None:
    files = make_run(tmp_path / "run", steps=(3000, 1000, 12000))
    found = snapshot_files(tmp_path / "run")
    assert [step for step, _ in found] == [1000, 3000, 12000]
    assert snapshot_files(tmp_path / "run" / "steps") == found
    windows = trailing_windows(found, [1, 3, 2, 1])
    assert [[step for step, _ in w] for w in windows] == [
        [1000, 3000, 12000],
        [3000, 12000],
        [12000],
    ]
    assert sorted(path for _, path in found) == sorted(files)
    with pytest.raises(ValueError, match=r"window size 4 is not in 1..3"):
        trailing_windows(found, [4])
    with pytest.raises(FileNotFoundError, match="no snapshot folder at .*missing"):
        snapshot_files(tmp_path / "missing")
    (tmp_path / "bare" / "steps").mkdir(parents=True)
    with pytest.raises(FileNotFoundError, match="no snapshots .*snapshots=true"):
        snapshot_files(tmp_path / "bare")


def test_windows_play_their_average_and_resume_from_the_cache(tmp_path, monkeypatch) -> None:
    files = make_run(tmp_path / "run")
    seeds = [5, 6, 7]
    results, best = select_window(tmp_path / "run", [1, 2, 3], ENV, seeds, tmp_path / "cache")
    assert [r.steps for r in results] == [[1000, 2000, 3000], [2000, 3000], [3000]]
    env = marl_cover.parallel_env(hops=2, **ENV)
    for result, window in zip(results, ([0, 1, 2], [1, 2], [2]), strict=True):
        paths = [files[i] for i in window]
        model = load_model(paths[0])[0] if len(paths) == 1 else average_models(paths)[0]
        direct = evaluate(env, GNNPolicy(model), seeds)
        assert result.rewards == [r.reward for r in direct.results]
    assert best.mean == max(r.mean for r in results)
    diff, _ = results[0].paired(results[2])
    assert diff == pytest.approx(results[0].mean - results[2].mean)

    def no_play(*args, **kwargs):
        raise AssertionError("a cached window was played again")

    monkeypatch.setattr("marl_cover.agents.evaluation.episodes.evaluate", no_play)
    again, best_again = select_window(tmp_path / "run", [3, 1, 2], ENV, seeds, tmp_path / "cache")
    assert [r.rewards for r in again] == [r.rewards for r in results]
    assert best_again.steps == best.steps
    with pytest.raises(ValueError, match=r"window_001000_003000.json: made under another setup"):
        select_window(tmp_path / "run", [3], ENV, [5, 6], tmp_path / "cache")


def test_ties_go_to_the_larger_window(tmp_path, monkeypatch) -> None:
    make_run(tmp_path / "run")
    monkeypatch.setattr(
        averaging,
        "evaluate_window",
        lambda window, *args: averaging.WindowResult(
            [s for s, _ in window], [str(p) for _, p in window], [1.0, 2.0]
        ),
    )
    _, best = select_window(tmp_path / "run", [1, 2, 3], ENV, [0, 1], tmp_path / "cache")
    assert best.steps == [1000, 2000, 3000]


def run_select(*args: str) -> subprocess.CompletedProcess:
    """``marl-cover average`` with ``args``."""
    return run_cli("average", *args)


def test_cli_writes_the_chosen_average(tmp_path) -> None:
    files = make_run(tmp_path / "run")
    out = tmp_path / "avg"
    result = run_select(
        f"run={tmp_path / 'run'}",
        *("sizes=[1,3]", "env.map=city", "episodes=2", "seed=3", f"out={out}"),
    )
    assert result.returncode == 0, result.stderr
    selection = json.loads((out / "selection.json").read_text())
    assert set(selection["windows"]) == {"steps 1000..3000 (3)", "steps 3000..3000 (1)"}
    chosen = selection["chosen"]
    assert f"{chosen}" in result.stdout and "<- best" in result.stdout
    model, metadata = load_model(out / "average.pt")
    expected = average_models(files)[0] if "(3)" in chosen else load_model(files[-1])[0]
    for key, value in expected.state_dict().items():
        assert torch.equal(model.state_dict()[key], value), key
    assert metadata["selection"]["chosen"] == chosen
    # a team and an episode length of the selection env's own (the mission's stand-in)
    team = run_select(
        f"run={tmp_path / 'run'}",
        *("sizes=[1]", "env.map=city", "env.num_robots=3", "env.max_steps=7"),
        *("episodes=2", "seed=3", f"out={tmp_path / 'team'}"),
    )
    assert team.returncode == 0, team.stderr
    (window,) = (tmp_path / "team" / "windows").iterdir()
    env = json.loads(window.read_text())["setup"]["env"]
    assert (env["num_robots"], env["max_steps"]) == (3, 7)
    missing = run_select(f"run={tmp_path / 'nothing'}")
    assert missing.returncode != 0 and "no snapshot folder" in missing.stderr
    assert not (tmp_path / "nothing").exists()
