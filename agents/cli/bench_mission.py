"""Speed of the quadrotor mission: simulated seconds per wall second, policy included.

Flies the mission of the ``mission`` preset (10 robots, 1266 waypoints, 400 s) with each method
on one CPU thread and reports the real-time factor with the time split between the simulation
(dynamics, visits, observations) and the policy. Target: >= 50x real time.

Example::

    marl-cover bench-mission methods=[greedy] seeds=[0] mission.dynamics.max_time=60
"""

from __future__ import annotations

import json
import platform
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from marl_cover.agents.cli.options import as_dict, load, parse
from marl_cover.agents.io import write_text_atomic
from marl_cover.agents.mission.flight import (
    MISSION_METHODS,
    MissionConfig,
    make_mission_policy,
    run_mission,
)
from marl_cover.config import require


def _mission() -> MissionConfig:
    return load(MissionConfig, "mission")


@dataclass
class BenchMissionConfig:
    """The methods, the seeds and the mission flown."""

    methods: list[str] = field(default_factory=lambda: ["greedy", "gnn", "expert"])  # flown
    seeds: list[int] = field(default_factory=lambda: [0, 1])  # one mission each
    out: str = "outputs/bench_mission.json"  # the JSON of every mission
    mission: MissionConfig = field(default_factory=_mission)  # the mission's settings

    def __post_init__(self) -> None:
        require(
            (set(self.methods) <= set(MISSION_METHODS), f"methods must be of {MISSION_METHODS}"),
            (bool(self.seeds) and min(self.seeds) >= 0, "seeds must be >= 0"),
        )


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover bench-mission") -> None:
    """``marl-cover bench-mission``: see the module docstring."""
    argv = sys.argv[1:] if argv is None else argv
    args = parse(BenchMissionConfig, argv, prog=prog, description=__doc__ or "")
    import torch

    torch.set_num_threads(1)
    config = args.mission
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
