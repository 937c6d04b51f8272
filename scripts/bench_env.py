"""Environment throughput: env steps/s and agent-steps/s with every robot's observation built.

Cases: (a) 4 robots on windows of the paper's map, K = 19; (b) 100 robots on the paper's
5659-waypoint map, K = 19; (c) the default procedural city. Random valid actions; resets
(new windows and cities) are included in the timing. Prints a table and writes JSON.

    python scripts/bench_env.py [--seconds 5] [--backend auto|numpy|numba]
                                [--out outputs/bench_env.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from marl_cover import parallel_env  # noqa: E402

CASES = {
    "a: paper windows, 4 robots, K=19": {"map": "paper", "num_robots": 4, "hops": 19},
    "b: paper 5659 map, 100 robots, K=19": {"map": "paper_large", "num_robots": 100, "hops": 19},
    "c: procedural city (defaults)": {},
}
TARGETS = {"a": 5000.0, "b": 100.0}


def observation_bytes(observations: dict) -> int:
    return sum(v.nbytes for obs in observations.values() for v in obs.values())


def bench(config: dict, seconds: float) -> dict:
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--out", type=Path, default=Path("outputs/bench_env.json"))
    parser.add_argument(
        "--backend",
        default="auto",
        choices=["auto", "numpy", "numba"],
        help="ego-graph builder (see CoverageConfig.ego_backend)",
    )
    args = parser.parse_args()
    results = {}
    print(
        f"{'case':<38} {'env steps/s':>12} {'agent-steps/s':>14} {'obs MB/step':>12} "
        f"{'step peak MB':>13} {'target':>8}"
    )
    for name, config in CASES.items():
        try:
            result = bench({**config, "ego_backend": args.backend}, args.seconds)
        except FileNotFoundError as error:  # the paper's map is not on this machine
            print(f"{name:<38} skipped: {error}")
            continue
        results[name] = result
        target = TARGETS.get(name[0])
        print(
            f"{name:<38} {result['env_steps_per_s']:12.0f} {result['agent_steps_per_s']:14.0f} "
            f"{result['observation_mb_per_step']:12.2f} {result['step_peak_mb']:13.2f} "
            f"{(f'>= {target:.0f}' if target else '-'):>8}",
            flush=True,
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
