"""Fuzz the environment: random maps, teams of 1..100 robots, both tasks, random, illegal and
malformed actions, with every invariant checked after every step
(:mod:`marl_cover.agents.evaluation.fuzz` lists them).

Prints the agent-steps run and the violations of each invariant, with the case that broke it;
``seed=S cases=[C]`` plays that case again alone. Exits 1 when anything was violated.

Example (about 10^5 agent-steps)::

    marl-cover fuzz agent_steps=100000 seed=0
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

from marl_cover.agents.cli.options import parse
from marl_cover.agents.io import progress_bar, write_text_atomic
from marl_cover.config import require


@dataclass
class FuzzConfig:
    """A fuzz run."""

    agent_steps: int = 100_000  # stop after the case that passes this many agent-steps
    seed: int = 0  # case C draws from numpy.random.default_rng([seed, C])
    max_robots: int = 100  # largest team
    max_waypoints: int = 400  # largest map
    illegal_fraction: float = 0.1  # chance that a robot's action is a masked-out one
    malformed_fraction: float = 0.05  # chance per step of a malformed action dict first
    replay_every: int = 10  # replay one case in this many, bit for bit (0: never)
    cases: list[int] = field(default_factory=list)  # play exactly these cases (empty: all)
    out: str = ""  # write the report as JSON here (empty: do not)

    def __post_init__(self) -> None:
        require(
            (self.agent_steps >= 1, f"agent_steps must be >= 1, got {self.agent_steps}"),
            (self.seed >= 0, f"seed must be >= 0, got {self.seed}"),
            (self.max_robots >= 1, f"max_robots must be >= 1, got {self.max_robots}"),
            (self.max_waypoints >= 10, f"max_waypoints must be >= 10, got {self.max_waypoints}"),
            (
                0.0 <= self.illegal_fraction <= 1.0 and 0.0 <= self.malformed_fraction <= 1.0,
                "illegal_fraction and malformed_fraction must be in [0, 1]",
            ),
            (self.replay_every >= 0, f"replay_every must be >= 0, got {self.replay_every}"),
            (all(c >= 0 for c in self.cases), f"cases must be >= 0, got {self.cases}"),
        )


def run(config: FuzzConfig) -> dict:
    """Runs the fuzzer, prints its table and returns the report as a dict."""
    from marl_cover.agents.evaluation.fuzz import fuzz

    bar = progress_bar("fuzz", unit="agent-step")
    tracker: Any = bar(total=config.agent_steps) if bar is not None and not config.cases else None
    report = fuzz(
        config.agent_steps,
        seed=config.seed,
        max_robots=config.max_robots,
        max_waypoints=config.max_waypoints,
        illegal_fraction=config.illegal_fraction,
        malformed_fraction=config.malformed_fraction,
        replay_every=config.replay_every,
        cases=config.cases or None,
        progress=None if tracker is None else tracker.update,
    )
    if tracker is not None:
        tracker.close()
    rate = report.agent_steps / max(report.seconds, 1e-9)
    print(
        f"{report.cases} cases, {report.env_steps} env steps, {report.agent_steps} agent-steps "
        f"in {report.seconds:.1f} s ({rate:,.0f} agent-steps/s); "
        f"{report.refused_inputs} bad action dicts refused as they should be"
    )
    print("| invariant | violations |\n|---|---|")
    for name, count in report.counts().items():
        print(f"| {name} | {count} |")
    for violation in report.violations[:20]:
        print(
            f"case {violation['case']} ({violation['invariant']}): {violation['message']}; "
            f"reproduce: marl-cover fuzz seed={config.seed} cases=[{violation['case']}]"
        )
    result = {
        "config": asdict(config),
        "cases": report.cases,
        "env_steps": report.env_steps,
        "agent_steps": report.agent_steps,
        "refused_inputs": report.refused_inputs,
        "seconds": report.seconds,
        "violations_by_invariant": report.counts(),
        "violations": report.violations,
        "settings": dict(sorted(report.settings.items())),
    }
    if config.out:
        write_text_atomic(config.out, json.dumps(result, indent=1))
    return result


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover fuzz") -> None:
    """``marl-cover fuzz``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    result = run(parse(FuzzConfig, args, prog=prog, description=__doc__ or ""))
    if result["violations"]:
        raise SystemExit(1)
