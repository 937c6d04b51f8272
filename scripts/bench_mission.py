"""Speed of the quadrotor mission: simulated seconds per wall second, policy included.

Flies the mission of ``configs/mission.yaml`` (10 robots, 1266 waypoints, 400 s) with each
method on one CPU thread and reports the real-time factor with the time split between the
simulation (dynamics, visits, observations) and the policy. Target: >= 50x real time.

    python scripts/bench_mission.py [--methods greedy gnn expert] [--seeds 0 1]
        [--out outputs/bench_mission.json] [key=value ...]   (mission config overrides)
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.cli import non_negative_int, write_text_atomic  # noqa: E402
from agents.configuration import as_dict, load_or_exit  # noqa: E402
from agents.mission import MISSION_METHODS, MissionConfig, make_mission_policy, run_mission  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", type=Path, default=Path("configs/mission.yaml"))
    parser.add_argument(
        "--methods", nargs="+", default=["greedy", "gnn", "expert"], choices=MISSION_METHODS
    )
    parser.add_argument("--seeds", nargs="+", type=non_negative_int, default=[0, 1])
    parser.add_argument("--out", type=Path, default=Path("outputs/bench_mission.json"))
    parser.add_argument("overrides", nargs="*")
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    config = load_or_exit(MissionConfig, args.config, args.overrides)
    env = config.make_env()
    rows = []
    print(
        f"{'method':10s} {'seed':>4s} {'sim s':>6s} {'wall s':>7s} {'policy s':>8s} "
        f"{'decisions':>9s} {'x real time':>11s}"
    )
    for method in args.methods:
        policy = make_mission_policy(method, config)
        if method == "gnn":  # warm-up (first torch calls)
            run_mission(env, policy, args.seeds[0])
        for seed in args.seeds:
            r = run_mission(env, policy, seed)
            rows.append(
                {
                    "method": method,
                    "seed": seed,
                    "mission_seconds": r.mission_seconds,
                    "wall_seconds": r.wall_seconds,
                    "policy_seconds": r.policy_seconds,
                    "decisions": r.decisions,
                    "real_time_factor": r.real_time_factor,
                }
            )
            print(
                f"{method:10s} {seed:4d} {r.mission_seconds:6.0f} {r.wall_seconds:7.2f} "
                f"{r.policy_seconds:8.2f} {r.decisions:9d} {r.real_time_factor:11.0f}"
            )
    summary = {
        m: float(np.min([row["real_time_factor"] for row in rows if row["method"] == m]))
        for m in args.methods
    }
    print(
        "slowest real-time factor per method: "
        + ", ".join(f"{m} {v:.0f}x" for m, v in summary.items())
        + "  (target >= 50x)"
    )
    write_text_atomic(
        args.out,
        json.dumps(
            {
                "machine": platform.processor() or platform.machine(),
                "threads": 1,
                "config": as_dict(config),
                "rows": rows,
                "min_real_time_factor": summary,
            },
            indent=1,
        ),
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
