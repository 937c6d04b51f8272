"""The benchmarks (``marl-cover bench``, ``bench-gnn``; ``scripts/bench_*.py``): their JSON
holds what their tables print, consistently."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from helpers import run_cli, run_script

from marl_cover import parallel_env

torch.set_num_threads(1)

WINDOWS = "a: paper windows, 4 robots, K=19"
CITY = "c: procedural city (defaults)"
BATCHED = "d: batched TorchRL env x2, collector"
WRAPPER = "e: PettingZooWrapper, collector"


@pytest.mark.usefixtures("paper_map_available")
def test_bench_env_rates_match_their_counts_and_targets(tmp_path: Path) -> None:
    """Each case's rate is its steps over its seconds, its agent-steps its robots' share, its
    observation size that of a real reset, and its target met exactly when the rate reaches it;
    ``cases`` runs the named cases only."""
    out = tmp_path / "bench_env.json"
    done = run_script("bench_env.py", "seconds=0.2", "cases=[c,a]", f"out={out}")
    assert done.returncode == 0, done.stderr
    results = json.loads(out.read_text())
    assert list(results) == [WINDOWS, CITY]  # the table's order, not the argument's
    for result in results.values():
        env = parallel_env(**result["config"])
        observations, _ = env.reset(seed=0)
        nbytes = sum(v.nbytes for obs in observations.values() for v in obs.values())
        assert result["observation_mb_per_step"] == nbytes / 2**20
        assert result["steps"] > 0
        assert result["env_steps_per_s"] == pytest.approx(result["steps"] / result["seconds"])
        assert result["agent_steps_per_s"] == pytest.approx(
            result["env_steps_per_s"] * env.config.num_robots
        )
        assert result["step_peak_mb"] > 0
    windows, city = results[WINDOWS], results[CITY]
    assert windows["target"] == 5000.0
    assert windows["meets_target"] == (windows["env_steps_per_s"] >= 5000.0)
    assert city["target"] is None and city["meets_target"] is None
    assert f"{WINDOWS:<38}" in done.stdout and ">= 5000" in done.stdout


@pytest.mark.usefixtures("paper_map_available")
def test_bench_env_collection_ratio_is_measured_in_the_same_run(tmp_path: Path) -> None:
    """Cases d and e collect whole batches (frames of ``num_envs`` episodes of 50 steps, and of
    100 steps) and their ratio is the quotient of the two rates."""
    out = tmp_path / "bench_env.json"
    args = ["seconds=0.2", "cases=[d,e]", "--num_envs", "2", f"out={out}"]
    done = run_cli("bench", *args)
    assert done.returncode == 0, done.stderr
    results = json.loads(out.read_text())
    assert list(results) == [BATCHED, WRAPPER, "ratio d / e"]
    batched, wrapper, ratio = results[BATCHED], results[WRAPPER], results["ratio d / e"]
    assert batched["config"]["num_envs"] == 2
    assert batched["frames"] % 100 == 0 and wrapper["frames"] % 100 == 0
    for result in (batched, wrapper):
        assert result["frames"] > 0
        assert result["frames_per_s"] == pytest.approx(result["frames"] / result["seconds"])
    assert ratio["ratio"] == pytest.approx(batched["frames_per_s"] / wrapper["frames_per_s"])
    assert ratio["target"] == 10.0 and batched["target"] == 2000.0 and wrapper["target"] is None
    assert ratio["meets_target"] == (ratio["ratio"] >= 10.0)
    assert batched["meets_target"] == (batched["frames_per_s"] >= 2000.0)


@pytest.mark.usefixtures("paper_map_available")
def test_bench_gnn_times_one_controller_in_every_mode(tmp_path: Path) -> None:
    """One row per model kind and case (4 robots at each K, then 100 robots at K = 19), the
    paper's time beside K = 9 and 19, a checkpoint's row at its own K, and the modes' logits
    equal: the decentralized, one-robot and centralized passes time the same controller."""
    from marl_cover.agents.models import AggregationGNN, GNNConfig
    from marl_cover.agents.models.checkpoints import save_model

    checkpoint = tmp_path / "wide.pt"
    save_model(checkpoint, AggregationGNN(GNNConfig(kind="nonlinear", hops=9, hidden=12)), {})
    out = tmp_path / "bench_gnn.json"
    args = ["hops=[3,9]", "steps=6", f"models=[{checkpoint}]", f"out={out}"]
    done = run_cli("bench-gnn", *args)
    assert done.returncode == 0, done.stderr
    rows = json.loads(out.read_text())["rows"]
    assert [(r["kind"], r["hops"], r["robots"]) for r in rows] == [
        ("linear", 3, 4),
        ("nonlinear", 3, 4),
        ("linear", 9, 4),
        ("nonlinear", 9, 4),
        (str(checkpoint), 9, 4),
        ("linear", 19, 100),
        ("nonlinear", 19, 100),
    ]
    assert [r["paper_ms"] for r in rows] == [None, None, 133 / 50, 176 / 50, None, None, None]
    assert rows[4]["hidden"] == 12
    for row in rows:
        assert row["max_logit_gap"] < 1e-4
        assert row["centralized_ms"] > 0
        if row["robots"] == 4:
            assert row["one_robot_ms"] > 0 and row["decentralized_ms"] > 0


def test_bench_scale_prints_rows_targets_and_the_pogema_row(tmp_path: Path, monkeypatch) -> None:
    """Case d (4 robots) with a stand-in for POGEMA's interpreter that is not there: the rows,
    the targets table and the JSON, and a POGEMA row that says it is absent."""
    monkeypatch.delenv("MARL_COVER_POGEMA_PYTHON", raising=False)
    out = tmp_path / "scale.json"
    args = ["cases=d", "seconds=0.2", "resets=1", f"out={out}"]
    done = run_cli("bench-scale", *args)
    assert done.returncode == 0, done.stderr
    assert "| d: 4 robots, hops 5, compact |" in done.stdout
    record = json.loads(out.read_text())
    rows = {row["name"]: row for row in record["rows"]}
    compact, padded = rows["d: 4 robots, hops 5, compact"], rows["d: 4 robots, hops 5, padded"]
    assert compact["agent_steps_per_s"] == pytest.approx(4 * compact["steps_per_s"])
    assert compact["obs_mb"] < padded["obs_mb"]  # the same ego-graphs without the padding
    assert rows["d: 4 agents, POGEMA, radius 5"]["mode"] == "pogema (absent)"
    assert "| d: 4 agents, POGEMA, radius 5 | - |" in done.stdout
