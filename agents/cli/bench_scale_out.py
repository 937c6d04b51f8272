"""Scale-out throughput: the same work serially and on 1 and 2 Ray workers, in one run.

Cases: (a) ``greedy_episodes`` greedy evaluation episodes (shards of ``shard_size`` seeds,
``marl-cover evaluate``'s task); (b) ``expert_episodes`` open-loop PyVRP expert episodes
(``marl-cover collect``'s task, shards of ``expert_shard_size``); (c) MAPPO collection frames/s
(TorchRL collectors on the batched environment: in the training process, and Ray's
``RayCollector`` with 1 and 2 workers). Ray starts once, before any timing; every figure is
wall time on this machine in this run. Prints a table and writes JSON with the targets: 2
workers >= 1.7x the 1-worker throughput for (a) and (b), and Ray at 1 worker within 15% of
serial.

Example::

    marl-cover bench-scale-out greedy_episodes=200 expert_episodes=20
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

from marl_cover import EnvSettings
from marl_cover.agents.cli.collect import CollectConfig, collect_shard
from marl_cover.agents.cli.evaluate import EvaluateConfig, evaluate_shard
from marl_cover.agents.cli.options import parse
from marl_cover.agents.distributed import RayOptions, WorkerOptions, run_tasks
from marl_cover.agents.distributed.executor import ray_init
from marl_cover.agents.io import write_text_atomic
from marl_cover.config import require

#: Throughput of 2 Ray workers over 1, and of Ray at 1 worker over serial, at least.
SPEEDUP_TARGET = 1.7
OVERHEAD_TARGET = 0.85


@dataclass
class BenchScaleOutConfig:
    """What is timed."""

    greedy_episodes: int = 200  # case a
    shard_size: int = 10  # case a: episodes per task
    expert_episodes: int = 20  # case b
    expert_shard_size: int = 2  # case b: episodes per task
    expert_iterations: int = 1500  # case b: PyVRP iterations per plan (deterministic)
    mappo_batches: int = 4  # case c: timed batches (after one warm-up batch)
    frames_per_batch: int = 400  # case c: env steps per batch, over all collectors
    cases: str = "abc"  # the cases to run
    out: str = "outputs/bench_scale_out.json"  # the JSON of every row

    def __post_init__(self) -> None:
        require(
            (min(self.greedy_episodes, self.expert_episodes) >= 1, "episodes must be >= 1"),
            (min(self.shard_size, self.expert_shard_size) >= 1, "shard sizes must be >= 1"),
            (self.mappo_batches >= 1, f"mappo_batches must be >= 1, got {self.mappo_batches}"),
            (set(self.cases) <= set("abc"), f"cases are letters of 'abc', got {self.cases!r}"),
        )


def timed(task: Callable[[Any], Any], jobs: list[Any], options: WorkerOptions) -> float:
    """Wall seconds to run every job where ``options`` says."""
    start = time.perf_counter()
    for _ in run_tasks(task, jobs, options):
        pass
    return time.perf_counter() - start


def task_rows(name: str, task: Callable[[Any], Any], jobs: list[Any], units: int) -> list[dict]:
    """Serial, Ray x1 and Ray x2 runs of ``jobs``: seconds and units per second. Each run
    first warms its workers (imports, compiled kernels) on one job each, untimed."""
    rows = []
    for label, options in (
        ("serial", WorkerOptions()),
        ("ray, 1 worker", WorkerOptions(backend="ray", workers=1)),
        ("ray, 2 workers", WorkerOptions(backend="ray", workers=2)),
    ):
        timed(task, jobs[:1] * options.workers, options)  # warm-up
        seconds = timed(task, jobs, options)
        rows.append({"case": name, "run": label, "seconds": seconds, "rate": units / seconds})
        print(f"  {name}, {label}: {seconds:.2f} s", flush=True)
    return rows


def greedy_case(config: BenchScaleOutConfig) -> list[dict]:
    """Case a: greedy evaluation episodes, as ``marl-cover evaluate`` shards them."""
    evaluation = EvaluateConfig(policy="greedy", episodes=config.greedy_episodes)
    seeds = list(range(config.greedy_episodes))
    size = config.shard_size
    jobs = [(evaluation, seeds[i : i + size]) for i in range(0, len(seeds), size)]
    name = f"a: {config.greedy_episodes} greedy episodes (episodes/s)"
    return task_rows(name, evaluate_shard, jobs, config.greedy_episodes)


def expert_case(config: BenchScaleOutConfig) -> list[dict]:
    """Case b: expert episodes recorded into shards, as ``marl-cover collect`` does."""
    collect = CollectConfig(env=EnvSettings(map="city"))
    settings = asdict(collect)
    settings["expert"]["iterations"] = config.expert_iterations
    size = config.expert_shard_size
    seeds = list(range(config.expert_episodes))
    jobs = [(i // size, seeds[i : i + size], settings) for i in range(0, len(seeds), size)]
    name = f"b: {config.expert_episodes} PyVRP expert episodes (episodes/s)"
    return task_rows(name, collect_shard, jobs, config.expert_episodes)


def mappo_case(config: BenchScaleOutConfig) -> list[dict]:
    """Case c: MAPPO collection, the learner's weights pushed after every batch."""
    import torch

    from marl_cover.agents.models.gnn import AggregationGNN
    from marl_cover.agents.training.mappo import _make_collector
    from marl_cover.agents.training.mappo_config import CollectorConfig, MAPPOConfig
    from marl_cover.agents.training.mappo_parts import build_actor

    torch.set_num_threads(1)
    rows = []
    name = "c: MAPPO collection (frames/s)"
    for label, backend, workers in (
        ("serial", "process", 1),
        ("ray, 1 worker", "ray", 1),
        ("ray, 2 workers", "ray", 2),
    ):
        collector_config = CollectorConfig(
            backend=backend,
            workers=workers,
            n_iters=config.mappo_batches + 1,
            frames_per_batch=config.frames_per_batch,
        )
        mappo = MAPPOConfig(env=EnvSettings(map="city"), collector=collector_config)
        actor = build_actor(AggregationGNN(mappo.model.actor), mappo, mappo.env.num_robots)
        collector = _make_collector(
            mappo, actor, torch.device("cpu"), collector_config.n_iters, seed=0
        )
        batches = iter(collector)
        next(batches)  # warm-up: remote actors start, environments reset
        start = time.perf_counter()
        for _ in range(config.mappo_batches):
            next(batches)
            collector.update_policy_weights_()
        seconds = time.perf_counter() - start
        collector.shutdown()
        frames = config.mappo_batches * config.frames_per_batch
        rows.append({"case": name, "run": label, "seconds": seconds, "rate": frames / seconds})
        print(f"  {name}, {label}: {seconds:.2f} s", flush=True)
    return rows


def checks(rows: list[dict]) -> list[dict]:
    """The targets of each case: 2 workers over 1, and Ray at 1 worker over serial."""
    out = []
    for case in dict.fromkeys(r["case"] for r in rows):
        rate = {r["run"]: r["rate"] for r in rows if r["case"] == case}
        speedup = rate["ray, 2 workers"] / rate["ray, 1 worker"]
        kept = rate["ray, 1 worker"] / rate["serial"]
        targeted = not case.startswith("c")
        out.append(
            {
                "case": case,
                "speedup_2_over_1": speedup,
                "ray_1_over_serial": kept,
                "met": (speedup >= SPEEDUP_TARGET and kept >= OVERHEAD_TARGET)
                if targeted
                else None,
            }
        )
    return out


def run(config: BenchScaleOutConfig) -> dict[str, Any]:
    """Runs the cases, prints the table, writes the JSON."""
    started = ray_init(RayOptions(), num_cpus=2)
    rows: list[dict] = []
    try:
        for letter, case in (("a", greedy_case), ("b", expert_case), ("c", mappo_case)):
            if letter in config.cases:
                rows += case(config)
    finally:
        if started:
            import ray

            ray.shutdown()
    summary = checks(rows)
    print(
        "| case | serial | ray, 1 worker | ray, 2 workers | 2 / 1 | ray 1 / serial | target met |"
    )
    print("|---|---|---|---|---|---|---|")
    for check in summary:
        rate = {r["run"]: r["rate"] for r in rows if r["case"] == check["case"]}
        met = {True: "yes", False: "NO", None: "(no target)"}[check["met"]]
        print(
            f"| {check['case']} | {rate['serial']:.1f} | {rate['ray, 1 worker']:.1f} | "
            f"{rate['ray, 2 workers']:.1f} | x{check['speedup_2_over_1']:.2f} | "
            f"{100 * check['ray_1_over_serial']:.0f}% | {met} |"
        )
    record = {"config": asdict(config), "rows": rows, "checks": summary}
    write_text_atomic(config.out, json.dumps(record, indent=1))
    print(f"wrote {config.out}")
    return record


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover bench-scale-out") -> None:
    """``marl-cover bench-scale-out``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    run(parse(BenchScaleOutConfig, args, prog=prog, description=__doc__ or ""))
