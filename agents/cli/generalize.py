"""10 to 100 robots on the paper's 5659-waypoint map, GNN beside greedy (the paper's Fig.
"generalize").

The GNN was trained with 4 robots on ~228-waypoint windows; here it runs on the paper's large
map (T = 50, K = the model's receptive field) in one centralized pass per step (the same actions
as each robot on its own ego-graph, tested). Greedy runs on each robot's ego-graph. Seeds are
paired across methods. Each (method, team size) result is written to
``out/<method>_R<robots>.json`` when done, with its setup (task, seeds, the model's SHA-256),
and read back when present (resumable); a file made under another setup is an error. Prints the
table beside the paper's numbers and draws ``out/generalize.png``.

Example::

    marl-cover generalize robots=[10,100] episodes=20
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from marl_cover import parallel_env
from marl_cover.agents.baselines.greedy import GreedyPolicy
from marl_cover.agents.cli.options import parse
from marl_cover.agents.evaluation.episodes import evaluate
from marl_cover.agents.evaluation.paper import paper_numbers
from marl_cover.agents.evaluation.plots import plot_beside_paper
from marl_cover.agents.io import file_sha256, read_json, read_result, write_text_atomic
from marl_cover.config import TASKS, require

PAPER_METHODS = {"greedy": "greedy", "gnn": "gnn_nonlinear_bc"}


@dataclass
class GeneralizeConfig:
    """Team sizes, seeds and the model."""

    task: str = "coverage"  # coverage or exploration
    robots: list[int] = field(default_factory=lambda: [10, 20, 30, 40, 50, 100])  # team sizes
    episodes: int = 100  # episodes per team size
    seed: int = 0  # first seed
    model: str | None = None  # a shipped name or a model file (None: the task's default)
    methods: list[str] = field(default_factory=lambda: ["greedy", "gnn"])  # greedy and/or gnn
    out: str = "outputs/generalize"  # results, table and plot
    table_only: bool = False  # print the table of the results on disk, run nothing

    def __post_init__(self) -> None:
        require(
            (self.task in TASKS, f"task must be one of {TASKS}, got {self.task!r}"),
            (all(r >= 1 for r in self.robots), f"robots must be >= 1, got {self.robots}"),
            (self.episodes >= 1 and self.seed >= 0, "episodes must be >= 1 and seed >= 0"),
            (set(self.methods) <= set(PAPER_METHODS), f"methods: greedy, gnn; {self.methods}"),
        )


def setup(method: str, robots: int, config: GeneralizeConfig, sha256: str) -> dict[str, Any]:
    """What decides one (method, team size) result: a file made under another is not reused."""
    return {
        "method": method,
        "task": config.task,
        "robots": robots,
        "episodes": config.episodes,
        "seed": config.seed,
        "model_sha256": sha256 if method == "gnn" else None,
    }


def play(method: str, robots: int, config: GeneralizeConfig, model: Any, sha: str) -> dict:
    """One (method, team size) result over the seeds."""
    hops = model.config.hops
    env = parallel_env(
        map="paper_large", num_robots=robots, hops=hops, max_steps=50, task=config.task
    )
    policy: Any
    if method == "gnn":
        from marl_cover.agents.models.policy import GNNPolicy

        policy = GNNPolicy(model, centralized=True)
    else:
        policy = GreedyPolicy(hops, fallback="random")
    summary = evaluate(env, policy, range(config.seed, config.seed + config.episodes))
    return {
        "method": method,
        "task": config.task,
        "robots": robots,
        "hops": hops,
        "episodes": config.episodes,
        "seed": config.seed,
        "model": config.model if method == "gnn" else None,
        "mean": summary.mean,
        "std": summary.std,
        "sem": summary.sem,
        "rewards": [r.reward for r in summary.results],
        "controller_ms_per_step": summary.controller_ms_per_step,
        "setup": setup(method, robots, config, sha),
    }


def table(records: dict, paper: dict) -> None:
    """Ours beside the paper's, per team size, with the ratio of the means."""
    print(
        f"{'R':>4} {'greedy ours':>16} {'GNN ours':>16} {'ratio (paired)':>18} "
        f"{'greedy paper':>16} {'GNN paper':>16}"
    )
    for robots in sorted({k[1] for k in records}):
        greedy, gnn = records.get(("greedy", robots)), records.get(("gnn", robots))
        cells = [f"{r['mean']:7.1f} +- {r['sem']:4.1f}" if r else "-" for r in (greedy, gnn)]
        ratio = "-"
        if greedy and gnn and len(greedy["rewards"]) == len(gnn["rewards"]):
            ratios = np.array(gnn["rewards"]) / np.maximum(np.array(greedy["rewards"]), 1)
            ratio = f"{gnn['mean'] / greedy['mean']:5.3f} ({np.median(ratios):.3f} med)"
        for name in ("greedy", "gnn"):
            value = paper.get((PAPER_METHODS[name], robots))
            cells.append(f"{value[0]:7.1f} +- {value[1]:4.1f}" if value else "-")
        print(
            f"{robots:>4} {cells[0]:>16} {cells[1]:>16} {ratio:>18} {cells[2]:>16} {cells[3]:>16}"
        )


def plot(records: dict, paper: dict, path: Path, task: str) -> None:
    """Mean +- SEM against team size, ours (solid) and the paper's (dashed)."""
    curves = {
        method: (
            [(k[1], r["mean"], r["sem"]) for k, r in records.items() if k[0] == method],
            [(k[1], *v) for k, v in paper.items() if k[0] == PAPER_METHODS[method]],
        )
        for method in ("greedy", "gnn")
    }
    plot_beside_paper(
        curves,
        path,
        "robots",
        "points of interest visited in 50 steps (mean +- SEM)",
        f"{task.capitalize()} on the 5659-waypoint map, K = 19",
    )


def run(config: GeneralizeConfig) -> None:
    """Plays the missing results, prints the table, draws the plot."""
    import torch

    from marl_cover.agents.models.checkpoints import load_model
    from marl_cover.agents.models.shipped import default_model, model_path

    torch.set_num_threads(1)
    try:
        path = model_path(config.model or default_model(config.task))
        model, _ = load_model(path)
    except (FileNotFoundError, ValueError) as error:
        raise SystemExit(f"marl-cover generalize: {error}") from None
    sha = file_sha256(path)  # names the model in each result's setup
    out = Path(config.out)
    if not config.table_only:
        for robots in config.robots:
            for method in config.methods:
                result = out / f"{method}_R{robots}.json"
                if result.exists():
                    read_result(result, setup(method, robots, config, sha))
                else:
                    record = play(method, robots, config, model, sha)
                    write_text_atomic(result, json.dumps(record, indent=2))
                    print(f"done {method} R={robots}", flush=True)
    records = {
        (r["method"], r["robots"]): r for r in (read_json(p) for p in sorted(out.glob("*_R*.json")))
    }
    paper = paper_numbers(f"{config.task}_generalize_5659")
    table(records, paper)
    if records:
        plot(records, paper, out / "generalize.png", config.task)
        print(f"wrote {out / 'generalize.png'}")


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover generalize") -> None:
    """``marl-cover generalize``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    run(parse(GeneralizeConfig, args, prog=prog, description=__doc__ or ""))
