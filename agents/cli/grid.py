"""A grid of evaluations (policies x K x maps x team sizes) as one job: one CSV, one plot.

Every cell is evaluated on the same seeds (paired); the cells' episodes are cut into shards of
``shard_size`` seeds and run where ``backend`` says (``ray`` spreads the whole grid over a
cluster at once, ``ray.address=auto``). The CSV holds one row per (cell, seed); the summary
table (mean +- SEM per cell) is printed and written as JSON; the plot shows the reward against
K, one curve per (policy, map, team size). Each episode is seeded by its own seed, so every
backend writes the same rows (the timing columns aside).

Example::

    marl-cover grid policies=[greedy,gnn] hops=[3,5,19] maps=[city] robots=[4,10] \\
        episodes=20 backend=ray workers=2
"""

from __future__ import annotations

import csv
import io
import json
import sys
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from marl_cover import EnvSettings
from marl_cover.agents.cli.evaluate import POLICIES, EvaluateConfig, evaluate_shard
from marl_cover.agents.cli.options import parse
from marl_cover.agents.distributed import WorkerOptions, run_tasks
from marl_cover.agents.io import progress_bar, write_text_atomic
from marl_cover.config import require

#: The columns of the grid's CSV.
COLUMNS = ("policy", "map", "robots", "hops", "seed", "reward", "coverage", "steps")


@dataclass
class GridConfig(WorkerOptions):
    """An evaluation grid, and where its shards run."""

    policies: list[str] = field(default_factory=lambda: ["greedy", "gnn"])  # from evaluate's
    hops: list[int] = field(default_factory=lambda: [3, 5, 19])  # the receptive fields K
    maps: list[str] = field(default_factory=lambda: ["city"])  # env.map values
    robots: list[int] = field(default_factory=lambda: [4])  # team sizes
    episodes: int = 20  # seeds per cell
    seed: int = 0  # first seed
    shard_size: int = 10  # episodes of one task
    out: str = "outputs/grid"  # grid.csv, grid.json and grid.png go here
    env: EnvSettings = field(default_factory=EnvSettings)  # the other env settings

    def __post_init__(self) -> None:
        super().__post_init__()
        if isinstance(self.env, dict):
            self.env = EnvSettings.from_dict(self.env)
        unknown = sorted(set(self.policies) - set(POLICIES))
        require(
            (not unknown, f"unknown policies {unknown}; policies: {list(POLICIES)}"),
            (all(self.policies) and self.policies != [], "policies must not be empty"),
            (bool(self.hops) and min(self.hops) >= 1, f"hops must be >= 1, got {self.hops}"),
            (bool(self.maps), "maps must not be empty"),
            (bool(self.robots) and min(self.robots) >= 1, f"robots must be >= 1: {self.robots}"),
            (self.episodes >= 1 and self.seed >= 0, "episodes must be >= 1 and seed >= 0"),
            (self.shard_size >= 1, f"shard_size must be >= 1, got {self.shard_size}"),
        )

    def cells(self) -> list[EvaluateConfig]:
        """One evaluation per (policy, map, team size, K), in grid order."""
        return [
            EvaluateConfig(
                policy=policy,
                episodes=self.episodes,
                seed=self.seed,
                shard_size=self.shard_size,
                env=replace(self.env, map=map_name, num_robots=robots, hops=hops),
            )
            for policy in self.policies
            for map_name in self.maps
            for robots in self.robots
            for hops in self.hops
        ]


def run(config: GridConfig) -> list[dict[str, Any]]:
    """Evaluates every cell, writes the CSV, the JSON summary and the plot; returns the
    summary rows."""
    cells = config.cells()
    seeds = list(range(config.seed, config.seed + config.episodes))
    size = config.shard_size
    jobs = [(cell, seeds[i : i + size]) for cell in cells for i in range(0, len(seeds), size)]
    owner = [index for index in range(len(cells)) for _ in range(0, len(seeds), size)]
    bar = progress_bar("grid", unit="shard")
    finished = run_tasks(evaluate_shard, jobs, config)
    ranked: list[tuple[int, int, dict[str, Any]]] = []  # (cell, seed, row)
    for job, results in bar(finished, total=len(jobs)) if bar else finished:
        cell = cells[owner[job]]
        ranked += [
            (
                owner[job],
                r.seed,
                {
                    "policy": cell.policy,
                    "map": cell.env.map,
                    "robots": cell.env.num_robots,
                    "hops": cell.env.hops,
                    "seed": r.seed,
                    "reward": r.reward,
                    "coverage": r.coverage,
                    "steps": r.steps,
                },
            )
            for r in results
        ]
    rows = [row for _, _, row in sorted(ranked, key=lambda item: item[:2])]
    out = Path(config.out)
    table = io.StringIO()
    writer = csv.DictWriter(table, fieldnames=list(COLUMNS))
    writer.writeheader()
    writer.writerows(rows)
    write_text_atomic(out / "grid.csv", table.getvalue())
    summary = summarize(rows, cells)
    write_text_atomic(
        out / "grid.json", json.dumps({"config": asdict(config), "cells": summary}, indent=1)
    )
    print("| policy | map | robots | K | reward (mean +- SEM) |\n|---|---|---|---|---|")
    for line in summary:
        print(
            f"| {line['policy']} | {line['map']} | {line['robots']} | {line['hops']} | "
            f"{line['mean']:.2f} +- {line['sem']:.2f} |"
        )
    plot(summary, out / "grid.png")
    print(f"wrote {out / 'grid.csv'}, {out / 'grid.json'} and {out / 'grid.png'}")
    return summary


def summarize(rows: list[dict[str, Any]], cells: list[EvaluateConfig]) -> list[dict[str, Any]]:
    """Mean and SEM of the reward of every cell, in grid order."""
    summary = []
    for cell in cells:
        key = (cell.policy, cell.env.map, cell.env.num_robots, cell.env.hops)
        rewards = [
            r["reward"] for r in rows if (r["policy"], r["map"], r["robots"], r["hops"]) == key
        ]
        summary.append(
            {
                "policy": key[0],
                "map": key[1],
                "robots": key[2],
                "hops": key[3],
                "episodes": len(rewards),
                "mean": float(np.mean(rewards)),
                "sem": float(stats.sem(rewards)) if len(rewards) > 1 else 0.0,
            }
        )
    return summary


def plot(summary: list[dict[str, Any]], path: Path) -> None:
    """Reward against K, one curve per (policy, map, team size); skipped without matplotlib."""
    try:
        from marl_cover.agents.evaluation.plots import plot_beside_paper

        curves: dict[str, tuple[list[tuple[float, ...]], list[tuple[float, ...]]]] = {}
        for cell in summary:
            label = f"{cell['policy']}, {cell['map']}, {cell['robots']} robots"
            curves.setdefault(label, ([], []))[0].append((cell["hops"], cell["mean"], cell["sem"]))
        plot_beside_paper(curves, path, "receptive field K (hops)", "reward", "evaluation grid")
    except ImportError:
        print("note: no plot (matplotlib is not installed: pip install 'marl-cover[render]')")


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover grid") -> None:
    """``marl-cover grid``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    run(parse(GridConfig, args, prog=prog, description=__doc__ or ""))
