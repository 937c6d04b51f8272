"""Long jobs across processes and Ray: the same results as serial, retries, nothing lost.

The Ray tests start a local instance (``ray.init(num_cpus=2)``); they are skipped where ray is
not installed (``pip install -e ".[ray]"``).
"""

from __future__ import annotations

import csv
import io
import json
import os
import sys
from pathlib import Path

import pytest
from helpers import TINY_DATASET, run_cli

from marl_cover import EnvSettings
from marl_cover.agents.cli.evaluate import EvaluateConfig, evaluate_shard, results_csv
from marl_cover.agents.distributed import WorkerOptions, run_tasks

TIMINGS = ("controller_seconds", "env_seconds")  # measured, so never equal across runs


def square(x: int) -> int:
    return x * x


def rows_without_timings(text: str) -> list[dict[str, str]]:
    rows = list(csv.DictReader(io.StringIO(text)))
    return [{k: v for k, v in row.items() if k not in TIMINGS} for row in rows]


@pytest.mark.parametrize("backend", ["serial", "process"])
def test_local_backends_give_every_result_once(backend: str) -> None:
    found = dict(run_tasks(square, list(range(7)), WorkerOptions(backend=backend, workers=2)))
    assert found == {i: i * i for i in range(7)}


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"backend": "spark"}, "backend must be one of ('serial', 'process', 'ray')"),
        ({"workers": 0}, "workers must be >= 1, got 0"),
        ({"ray": {"max_retries": -1}}, "ray.max_retries must be >= 0"),
    ],
)
def test_bad_worker_settings_are_named(settings: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        WorkerOptions(**settings)


# ---------------------------------------------------------------------- Ray
ray = pytest.importorskip("ray", reason="ray is not installed (pip install -e '.[ray]')")


@pytest.fixture(scope="module")
def local_ray():
    if not ray.is_initialized():
        ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])  # FailOnce below
    yield
    ray.shutdown()


class FailOnce:
    """A task that dies (the worker exits) or raises the first time, then runs ``task``."""

    def __init__(self, task, marker: Path, how: str) -> None:  # noqa: ANN001
        self.task, self.marker, self.how = task, marker, how

    def __call__(self, argument):  # noqa: ANN001, ANN204
        if not self.marker.exists():
            self.marker.write_text("failed once")
            if self.how == "exit":
                os._exit(1)
            raise RuntimeError("a flaky worker")
        return self.task(argument)


def test_ray_runs_every_task_once(local_ray) -> None:
    options = WorkerOptions(backend="ray", workers=2)
    found = list(run_tasks(square, list(range(9)), options))
    assert sorted(found) == [(i, i * i) for i in range(9)]


@pytest.mark.parametrize("how", ["exit", "raise"])
def test_a_failed_worker_is_retried_and_the_csv_is_the_same(local_ray, tmp_path, how) -> None:
    config = EvaluateConfig(
        policy="greedy", episodes=6, seed=3, shard_size=2, env=EnvSettings(city_size=120)
    )
    jobs = [(config, [3, 4]), (config, [5, 6]), (config, [7, 8])]
    serial = [r for _, part in run_tasks(evaluate_shard, jobs, WorkerOptions()) for r in part]
    flaky = FailOnce(evaluate_shard, tmp_path / "marker", how)
    options = WorkerOptions(backend="ray", workers=2)
    parts = dict(run_tasks(flaky, jobs, options))
    assert (tmp_path / "marker").exists()  # one task did fail
    assert sorted(parts) == [0, 1, 2]  # each shard once
    again = sorted((r for part in parts.values() for r in part), key=lambda r: r.seed)
    assert rows_without_timings(results_csv(again)) == rows_without_timings(results_csv(serial))


def test_evaluation_through_ray_writes_the_serial_rows(tmp_path) -> None:
    common = ["policy=greedy", "episodes=6", "seed=10", "shard_size=2", "env.city_size=120"]
    serial = run_cli("evaluate", *common, f"out={tmp_path / 'serial.json'}")
    assert serial.returncode == 0, serial.stderr
    through_ray = run_cli(
        "evaluate", *common, "backend=ray", "workers=2", f"out={tmp_path / 'ray.json'}"
    )
    assert through_ray.returncode == 0, through_ray.stderr
    texts = [(tmp_path / f"{name}.csv").read_text() for name in ("serial", "ray")]
    assert rows_without_timings(texts[0]) == rows_without_timings(texts[1])
    assert [row["seed"] for row in rows_without_timings(texts[1])] == [
        str(s) for s in range(10, 16)
    ]


def test_a_dataset_collected_through_ray_is_the_serial_one(tmp_path) -> None:
    pytest.importorskip("pyvrp")
    for name, backend in (("serial", ["backend=serial"]), ("ray", ["backend=ray", "workers=2"])):
        done = run_cli("collect", *TINY_DATASET, *backend, f"out={tmp_path / name}")
        assert done.returncode == 0, done.stderr
    for shard in ("shard_00000.npz", "shard_00001.npz", "shard_00002.npz"):
        assert (tmp_path / "serial" / shard).read_bytes() == (tmp_path / "ray" / shard).read_bytes()


def test_mappo_collects_through_ray_and_writes_a_checkpoint(tmp_path) -> None:
    pytest.importorskip("torchrl")
    out = tmp_path / "mappo"
    done = run_cli(
        "train-mappo",
        "collector.n_iters=2",
        "collector.frames_per_batch=200",
        "collector.backend=ray",
        "collector.workers=2",
        "env.map=city",
        "eval.episodes=2",
        "progress=false",
        f"out={out}",
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "weight synchronization was initialized" not in done.stderr
    summary = json.loads(done.stdout)
    assert summary["iteration"] == 2 and summary["frames"] == 400.0
    for name in ("checkpoint.pt", "best.pt", "model.pt", "curve.json"):
        assert (out / name).is_file(), name


def test_the_remote_collectors_get_the_learners_weights(local_ray) -> None:
    torch = pytest.importorskip("torch")
    from marl_cover.agents.models.gnn import AggregationGNN
    from marl_cover.agents.training.mappo import _make_collector
    from marl_cover.agents.training.mappo_config import CollectorConfig, MAPPOConfig
    from marl_cover.agents.training.mappo_parts import build_actor

    collector_config = CollectorConfig(backend="ray", workers=2, n_iters=2, frames_per_batch=200)
    config = MAPPOConfig(env=EnvSettings(map="city"), collector=collector_config)
    gnn = AggregationGNN(config.model.actor)
    actor = build_actor(gnn, config, 4)
    collector = _make_collector(config, actor, torch.device("cpu"), 2, 0)

    def remote_weights() -> list[dict]:
        remotes = collector.remote_collectors
        return ray.get([r.cascade_execute.remote("policy.state_dict") for r in remotes])

    try:
        batches = iter(collector)
        next(batches)
        with torch.no_grad():
            for parameter in gnn.parameters():
                parameter.add_(1.0)  # a learner's update
        collector.update_policy_weights_()
        next(batches)
        for weights in remote_weights():
            for name, tensor in actor.state_dict().items():
                assert torch.equal(weights[name], tensor), name
    finally:
        collector.shutdown()


def test_a_grid_through_ray_is_the_serial_grid(tmp_path) -> None:
    common = [
        "policies=[greedy,greedy_central]",
        "hops=[2,5]",
        "robots=[3,5]",
        "episodes=4",
        "shard_size=2",
        "env.city_size=100",
        "env.max_steps=20",
    ]
    serial = run_cli("grid", *common, f"out={tmp_path / 'serial'}")
    assert serial.returncode == 0, serial.stderr
    through_ray = run_cli("grid", *common, "backend=ray", "workers=2", f"out={tmp_path / 'ray'}")
    assert through_ray.returncode == 0, through_ray.stderr
    texts = [(tmp_path / name / "grid.csv").read_text() for name in ("serial", "ray")]
    assert texts[0] == texts[1]
    rows = list(csv.DictReader(io.StringIO(texts[0])))
    assert len(rows) == 2 * 2 * 2 * 4
    assert [r["seed"] for r in rows[:4]] == ["0", "1", "2", "3"]
    cells = json.loads((tmp_path / "ray" / "grid.json").read_text())["cells"]
    assert [(c["policy"], c["robots"], c["hops"]) for c in cells[:3]] == [
        ("greedy", 3, 2),
        ("greedy", 3, 5),
        ("greedy", 5, 2),
    ]
    # greedy on the robots' ego-graphs and on the state choose the same moves
    for a, b in zip(cells[:4], cells[4:], strict=True):
        assert a["mean"] == b["mean"]
    assert "| greedy | city | 3 | 2 |" in through_ray.stdout
    assert (tmp_path / "ray" / "grid.png").is_file()
