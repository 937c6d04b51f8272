"""Evaluate a policy over fixed episode seeds (paired across methods); writes JSON and CSV.

    python scripts/evaluate.py task=coverage policy=greedy hops=19 episodes=100 seed=0 \\
        map=paper out=results.json
    python scripts/evaluate.py policy=expert expert.backend=ortools expert.time_limit=1.0
    python scripts/evaluate.py policy=expert_rh hops=19 expert.time_limit=0.15

Policies: ``greedy`` (each robot on its ego-graph), ``greedy_central`` (same actions, from
``state()``), ``expert`` (open-loop routing), ``expert_rh`` (receding horizon over ``hops``).
Maps: ``city`` (default), ``paper`` (windows of the paper's map), ``paper_full``,
``paper_large``, or a grid file. Any other ``key=value`` is a field of ``CoverageConfig``
(``num_robots=10``, ``max_steps=49``, ...); an unknown key is an error.
"""

from __future__ import annotations

import csv
import io
import json
import sys
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.cli import parse_value, write_text_atomic  # noqa: E402
from agents.evaluation import evaluate  # noqa: E402
from marl_cover import CoverageConfig, parallel_env  # noqa: E402

POLICIES = ("greedy", "greedy_central", "expert", "expert_rh")


@dataclass
class ExpertOptions:
    backend: str = "pyvrp"
    time_limit: float = 0.9
    seed: int = 0
    warm_start: bool = True


@dataclass
class EvaluateOptions:
    task: str = "coverage"
    policy: str = "greedy"
    episodes: int = 100
    seed: int = 0
    out: str = "outputs/evaluate.json"
    fallback: str = "random"  # greedy's choice when nothing is in reach


def parse_overrides(argv: list[str]) -> tuple[EvaluateOptions, ExpertOptions, dict[str, Any]]:
    """Splits ``key=value`` arguments into script, expert and environment options.

    Raises:
        SystemExit: a malformed argument or an unknown key, naming it.
    """
    options, expert, env = EvaluateOptions(), ExpertOptions(), {}
    env_keys = {f.name for f in fields(CoverageConfig)} - {"graph", "render_mode"}
    for arg in argv:
        if "=" not in arg:
            raise SystemExit(f"arguments are key=value overrides, got {arg!r}")
        key, text = arg.split("=", 1)
        value = parse_value(text)
        if key.startswith("expert."):
            name = key.removeprefix("expert.")
            if name not in {f.name for f in fields(ExpertOptions)}:
                raise SystemExit(
                    f"unknown key {key!r}; expert keys: "
                    f"{sorted('expert.' + f.name for f in fields(ExpertOptions))}"
                )
            setattr(expert, name, value)
        elif key in {f.name for f in fields(EvaluateOptions)}:
            setattr(options, key, value if key != "out" else text)
        elif key in env_keys:
            env[key] = value if key != "map" else text
        else:
            raise SystemExit(
                f"unknown key {key!r}; script keys "
                f"{sorted(f.name for f in fields(EvaluateOptions))}, environment "
                f"keys {sorted(env_keys)}, and expert.*"
            )
    if options.task != "coverage":
        raise SystemExit(f"task {options.task!r} is not available yet; tasks: ['coverage']")
    if options.policy not in POLICIES:
        raise SystemExit(f"unknown policy {options.policy!r}; policies: {list(POLICIES)}")
    return options, expert, env


def make_policy(options: EvaluateOptions, expert: ExpertOptions, hops: int) -> Any:
    if options.policy in ("greedy", "greedy_central"):
        from agents.greedy import CentralizedGreedyPolicy, GreedyPolicy

        cls = GreedyPolicy if options.policy == "greedy" else CentralizedGreedyPolicy
        return cls(hops, fallback=options.fallback)
    from agents.experts import RoutingExpert

    receding = options.policy == "expert_rh"
    return RoutingExpert(
        backend=expert.backend,
        mode="receding" if receding else "open_loop",
        horizon=hops if receding else None,
        time_limit=expert.time_limit,
        seed=expert.seed,
        warm_start=expert.warm_start,
    )


def main(argv: list[str]) -> None:
    options, expert, env_overrides = parse_overrides(argv)
    env = parallel_env(**env_overrides)
    policy = make_policy(options, expert, env.config.hops)
    seeds = range(options.seed, options.seed + options.episodes)
    try:
        from tqdm import tqdm

        def progress(it):  # noqa: ANN001, ANN202
            return tqdm(it, desc=options.policy, unit="episode", file=sys.stderr)
    except ImportError:
        progress = None
    summary = evaluate(env, policy, seeds, progress=progress)
    record = {
        "options": asdict(options),
        "expert": asdict(expert) if options.policy.startswith("expert") else None,
        "env": {k: v for k, v in asdict(env.config).items() if k != "graph"},
        "summary": summary.as_dict(),
    }
    out = Path(options.out)
    write_text_atomic(out, json.dumps(record, indent=2))
    rows = [asdict(r) for r in summary.results]
    table = io.StringIO()
    writer = csv.DictWriter(table, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
    write_text_atomic(out.with_suffix(".csv"), table.getvalue())
    print(
        f"{options.policy} on {env.config.map}, {summary.episodes} episodes "
        f"(seeds {seeds.start}..{seeds.stop - 1}): reward {summary.mean:.2f} +- "
        f"{summary.sem:.2f} (SEM), std {summary.std:.2f}, 95% CI [{summary.ci95_low:.2f}, "
        f"{summary.ci95_high:.2f}], coverage {100 * summary.mean_coverage:.1f}%, controller "
        f"{summary.controller_ms_per_step:.2f} ms/step, env {summary.env_ms_per_step:.2f} "
        f"ms/step, counts {summary.policy_counts}"
    )
    print(f"wrote {out} and {out.with_suffix('.csv')}")


if __name__ == "__main__":
    main(sys.argv[1:])
