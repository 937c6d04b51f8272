"""Environment throughput: env steps/s and agent-steps/s with every robot's observation built.

PettingZoo cases: (a) 4 robots on windows of the paper's map, K = 19; (b) 100 robots on the
paper's 5659-waypoint map, K = 19; (c) the default procedural city; (f) and (g): cases a and b
on the exploration task (22 m sensor; discovery, the known graph and the frontier updated every
step). Random actions; resets (new windows and cities) are included in the timing.

TorchRL collection (case a's task, every robot's ego-graph and the state in every frame, random
actions from the action spec, a TorchRL ``Collector``): (d) the batched environment
(:class:`~marl_cover.agents.training.batched_env.BatchedCoverageEnv`, ``num_envs`` episodes a step)
beside (e) TorchRL's ``PettingZooWrapper`` around the PettingZoo env; frames are env steps, and the
ratio d / e is measured in the same run. Prints a table and writes JSON.

``cases`` runs the named cases only (``d`` and ``e`` run together: their ratio is one
measurement). Each case's JSON entry holds its target (``null`` where it has none) and whether
it was met; an interrupted run writes nothing.

Example::

    marl-cover bench cases=[a,c] seconds=2
"""

from __future__ import annotations

import json
import sys
import time
import tracemalloc
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from marl_cover import parallel_env
from marl_cover.agents.cli.options import parse
from marl_cover.agents.io import write_text_atomic
from marl_cover.config import require

CASES = {
    "a: paper windows, 4 robots, K=19": {"map": "paper", "num_robots": 4, "hops": 19},
    "b: paper 5659 map, 100 robots, K=19": {"map": "paper_large", "num_robots": 100, "hops": 19},
    "c: procedural city (defaults)": {},
    "f: exploration, paper windows, 4 robots": {
        "task": "exploration",
        "map": "paper",
        "num_robots": 4,
        "hops": 19,
    },
    "g: exploration, 5659 map, 100 robots": {
        "task": "exploration",
        "map": "paper_large",
        "num_robots": 100,
        "hops": 19,
    },
}
#: Env steps (frames for d) per second each case must keep, by its letter.
TARGETS = {"a": 5000.0, "b": 100.0, "d": 2000.0, "f": 3000.0, "g": 60.0}
#: The batched env's collection must be this many times faster than the wrapper's (d / e).
RATIO_TARGET = 10.0
LETTERS = ("a", "b", "c", "d", "e", "f", "g")
COLLECTION: dict[str, Any] = {"map": "paper", "num_robots": 4, "hops": 19}


def observation_bytes(observations: dict) -> int:
    """Bytes of every robot's observation arrays."""
    return sum(v.nbytes for obs in observations.values() for v in obs.values())


def bench(config: dict, seconds: float) -> dict:
    """Env steps/s of the PettingZoo env under ``config`` with random actions, resets
    included, and the memory of one step."""
    env = parallel_env(**config)
    rng = np.random.default_rng(0)
    observations, _ = env.reset(seed=0)
    obs_bytes = observation_bytes(observations)
    # peak memory of one step (observations included), traced once outside the timing
    tracemalloc.start()
    actions = {
        a: int(rng.choice(np.flatnonzero(o["action_mask"]))) for a, o in observations.items()
    }
    env.step(actions)
    step_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    observations, _ = env.reset(seed=1)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        actions = {a: int(rng.integers(5)) for a in env.agents}
        observations, *_ = env.step(actions)
        steps += 1
        if not env.agents:
            observations, _ = env.reset()
    elapsed = time.perf_counter() - start
    return {
        "config": config,
        "env_steps_per_s": steps / elapsed,
        "agent_steps_per_s": steps * env.config.num_robots / elapsed,
        "observation_mb_per_step": obs_bytes / 2**20,
        "step_peak_mb": step_peak / 2**20,
        "steps": steps,
        "seconds": elapsed,
    }


def bench_collector(env, frames_per_batch: int, seconds: float) -> dict:  # noqa: ANN001
    """Frames (env steps) per second of a TorchRL ``Collector`` with random actions; the first
    batch (warm-up) is not timed."""
    import torch
    from torchrl.collectors import Collector

    torch.manual_seed(0)
    env.set_seed(0)
    collector = Collector(
        env, None, frames_per_batch=frames_per_batch, total_frames=-1, return_same_td=True
    )
    frames, start = 0, 0.0
    for k, batch in enumerate(collector):
        if k == 0:  # the first batch warms up; the clock starts after it
            start = time.perf_counter()
            continue
        frames += batch.numel()
        if time.perf_counter() - start >= seconds:
            break
    elapsed = time.perf_counter() - start
    collector.shutdown()
    return {"frames_per_s": frames / elapsed, "frames": frames, "seconds": elapsed}


def collection_cases(seconds: float, num_envs: int, backend: str) -> dict:
    """Cases d and e: the batched env and ``PettingZooWrapper`` under the same collector."""
    import torch
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

    from marl_cover.agents.training.batched_env import BatchedCoverageEnv

    torch.set_num_threads(1)
    config = {**COLLECTION, "ego_backend": backend}
    batched = BatchedCoverageEnv(num_envs, **config)
    wrapped = PettingZooWrapper(parallel_env(**config), return_state=True, use_mask=True)
    return {
        f"d: batched TorchRL env x{num_envs}, collector": {
            "config": {**config, "num_envs": num_envs},
            **bench_collector(batched, num_envs * 50, seconds),
        },
        "e: PettingZooWrapper, collector": {
            "config": config,
            **bench_collector(wrapped, 100, seconds),
        },
    }


def print_row(
    name: str, env_steps: float, agent_steps: float, obs_mb: str = "", peak_mb: str = ""
) -> None:
    """One line of the table (the case's target is looked up by its letter)."""
    target = TARGETS.get(name[0])
    print(
        f"{name:<38} {env_steps:12.0f} {agent_steps:14.0f} {obs_mb:>12} {peak_mb:>13} "
        f"{(f'>= {target:.0f}' if target else '-'):>8}",
        flush=True,
    )


def with_target(name: str, result: dict, rate: float) -> dict:
    """``result`` with its case's target and whether ``rate`` met it."""
    target = TARGETS.get(name[0])
    return {**result, "target": target, "meets_target": None if target is None else rate >= target}


def run_collection(cases, label: str, args: BenchEnvConfig, results: dict) -> dict:  # noqa: ANN001
    """Runs collection ``cases(seconds, num_envs, backend)`` (skipped without the paper's map),
    prints their rows and adds them to ``results``; returns them."""
    try:
        collected = cases(args.seconds, args.num_envs, args.backend)
    except FileNotFoundError as error:
        print(f"{label:<38} skipped: {error}")
        return {}
    for name, result in collected.items():
        results[name] = with_target(name, result, result["frames_per_s"])
        frames = result["frames_per_s"]
        print_row(name, frames, frames * COLLECTION["num_robots"])
    return collected


@dataclass
class BenchEnvConfig:
    """The cases and how long each runs."""

    seconds: float = 5.0  # seconds of stepping per case
    out: str = "outputs/bench_env.json"  # the JSON of every case
    backend: str = "auto"  # the ego-graph builder: auto, numpy or numba
    num_envs: int = 16  # the batched env's size (case d)
    cases: list[str] = field(default_factory=lambda: list(LETTERS))  # the letters to run
    skip_collectors: bool = False  # PettingZoo cases only (no d, e)

    def __post_init__(self) -> None:
        require(
            (self.seconds > 0 and self.num_envs >= 1, "seconds must be > 0, num_envs >= 1"),
            (set(self.cases) <= set(LETTERS), f"cases must be of {list(LETTERS)}"),
            (self.backend in ("auto", "numpy", "numba"), f"backend: {self.backend!r}"),
        )


def run(args: BenchEnvConfig) -> dict[str, Any]:
    """Runs the cases, prints the table, writes the JSON."""
    cases = set(args.cases) - ({"d", "e"} if args.skip_collectors else set())
    results: dict[str, Any] = {}
    print(
        f"{'case':<38} {'env steps/s':>12} {'agent-steps/s':>14} {'obs MB/step':>12} "
        f"{'step peak MB':>13} {'target':>8}"
    )
    for name, config in CASES.items():
        if name[0] not in cases:
            continue
        try:
            result = bench({**config, "ego_backend": args.backend}, args.seconds)
        except FileNotFoundError as error:  # the paper's map is not on this machine
            print(f"{name:<38} skipped: {error}")
            continue
        results[name] = with_target(name, result, result["env_steps_per_s"])
        print_row(
            name,
            result["env_steps_per_s"],
            result["agent_steps_per_s"],
            f"{result['observation_mb_per_step']:.2f}",
            f"{result['step_peak_mb']:.2f}",
        )
    if cases & {"d", "e"}:
        collected = run_collection(collection_cases, "d, e: TorchRL collection", args, results)
        if len(collected) == 2:
            d, e = (r["frames_per_s"] for r in collected.values())
            results["ratio d / e"] = {
                "ratio": d / e,
                "target": RATIO_TARGET,
                "meets_target": d / e >= RATIO_TARGET,
            }
            print(f"{f'ratio d / e (target >= {RATIO_TARGET:.0f})':<38} {d / e:12.1f}")
    write_text_atomic(args.out, json.dumps(results, indent=2))
    print(f"wrote {args.out}")
    return results


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover bench") -> None:
    """``marl-cover bench``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    run(parse(BenchEnvConfig, args, prog=prog, description=__doc__ or ""))
