"""The paper's receptive-field sweeps (Figs. "coverage", "exploration"): greedy, the
receding-horizon expert and the GNNs against K, beside the paper's numbers.

Runs each method for each K on seeded windows of the paper's map (4 robots, T = 50; greedy also
with T = 49, what the paper's code ran), prints mean +- SEM beside the paper's published figures
and draws mean +- SEM against K to ``out/<task>.png``. The GNN rows (``gnn_linear``,
``gnn_nonlinear``) evaluate ``models/<kind>_k<K>/best.pt`` (decentralized, argmax), as trained by
``marl-cover sweep``. Each (method, K) result is written to ``out/<method>_K<k>.json`` when done
and skipped when present: the sweep resumes after an interrupt and can be split over processes.
In exploration the expert is the fair one (it plans only on what the team has discovered).

Example::

    marl-cover reproduce-paper methods=[greedy] hops=[3,19] episodes=20
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from marl_cover import parallel_env
from marl_cover.agents.baselines.greedy import GreedyPolicy
from marl_cover.agents.cli.options import parse
from marl_cover.agents.evaluation.episodes import evaluate
from marl_cover.agents.evaluation.paper import paper_numbers
from marl_cover.agents.evaluation.plots import plot_beside_paper
from marl_cover.agents.io import read_json, write_text_atomic
from marl_cover.config import TASKS, require

HOPS = list(range(3, 20, 2))
#: Our method names -> the paper's, and the episode lengths each is run with.
METHODS = {
    "greedy": ("greedy", (50, 49)),
    "expert_rh": ("expert_receding_horizon", (50,)),
    "gnn_linear": ("gnn_linear_bc", (50,)),
    "gnn_nonlinear": ("gnn_nonlinear_bc", (50,)),
}


@dataclass
class ReproduceConfig:
    """Methods, receptive fields and seeds of the sweep."""

    task: str = "coverage"  # coverage or exploration
    methods: list[str] = field(default_factory=lambda: list(METHODS))  # of METHODS
    hops: list[int] = field(default_factory=lambda: list(HOPS))  # receptive fields K
    episodes: int = 100  # episodes per (method, K)
    seed: int = 0  # first episode seed
    backend: str = "pyvrp"  # the expert's solver: pyvrp or ortools
    expert_time_limit: float = 0.15  # seconds per expert plan
    out: str = "outputs/paper"  # results, table and plot
    models: str = "outputs/bc"  # the GNN runs, models/<kind>_k<K>/best.pt
    table_only: bool = False  # print the table of the results on disk, run nothing

    def __post_init__(self) -> None:
        require(
            (self.task in TASKS, f"task must be one of {TASKS}, got {self.task!r}"),
            (set(self.methods) <= set(METHODS), f"methods must be of {list(METHODS)}"),
            (all(k >= 1 for k in self.hops), f"hops must be >= 1, got {self.hops}"),
            (self.episodes >= 1 and self.seed >= 0, "episodes must be >= 1 and seed >= 0"),
            (self.expert_time_limit > 0, "expert_time_limit must be > 0"),
        )


def gnn_path(method: str, hops: int, config: ReproduceConfig) -> Path:
    """The model file of a GNN row."""
    return Path(config.models) / f"{method.removeprefix('gnn_')}_k{hops}" / "best.pt"


def make_policy(method: str, hops: int, config: ReproduceConfig) -> Any:
    """The policy of one row."""
    if method == "greedy":
        return GreedyPolicy(hops, fallback="random")
    if method.startswith("gnn_"):
        import torch

        from marl_cover.agents.models.checkpoints import load_model
        from marl_cover.agents.models.policy import GNNPolicy

        torch.set_num_threads(1)
        model, _ = load_model(gnn_path(method, hops, config))
        return GNNPolicy(model)
    from marl_cover.agents.experts import RoutingExpert

    return RoutingExpert(
        backend=config.backend,
        mode="receding",
        horizon=hops,
        time_limit=config.expert_time_limit,
        information="known" if config.task == "exploration" else "full",
    )


def play(method: str, hops: int, config: ReproduceConfig) -> dict:
    """One (method, K) result, at each of its episode lengths."""
    seeds = range(config.seed, config.seed + config.episodes)
    record: dict[str, Any] = {
        "task": config.task,
        "method": method,
        "hops": hops,
        "episodes": config.episodes,
        "seed": config.seed,
    }
    if method == "expert_rh":
        record["expert"] = {"backend": config.backend, "time_limit": config.expert_time_limit}
    if method.startswith("gnn_"):
        record["model"] = {"path": str(gnn_path(method, hops, config))}
    for steps in METHODS[method][1]:
        env = parallel_env(map="paper", hops=hops, max_steps=steps, task=config.task)
        summary = evaluate(env, make_policy(method, hops, config), seeds)
        record[f"T{steps}"] = {
            "mean": summary.mean,
            "std": summary.std,
            "sem": summary.sem,
            "controller_ms_per_step": summary.controller_ms_per_step,
            "counts": summary.policy_counts,
        }
    return record


def print_table(records: list[dict], task: str) -> None:
    """Mean +- SEM per K, ours and the paper's."""
    paper = paper_numbers(task)
    by_key = {(r["method"], r["hops"]): r for r in records}
    columns = []
    for method, (paper_name, lengths) in METHODS.items():
        for steps in lengths:
            columns.append((f"{method} T={steps}", method, f"T{steps}"))
        columns.append((f"paper {method}", paper_name, "paper"))
    print(f"{'K':>3}" + "".join(f"{name:>20}" for name, *_ in columns))
    for hops in HOPS:
        cells = []
        for _, method, key in columns:
            if key == "paper":
                value = paper.get((method, hops))
            else:
                record = by_key.get((method, hops), {}).get(key)
                value = (record["mean"], record["sem"]) if record else None
            cells.append(f"{value[0]:6.1f} +- {value[1]:4.2f}" if value else "-")
        print(f"{hops:>3}" + "".join(f"{c:>20}" for c in cells))


def plot(records: list[dict], path: Path, task: str) -> None:
    """Mean +- SEM against K, ours (solid) and the paper's (dashed)."""
    paper = paper_numbers(task)
    curves = {
        method: (
            [
                (r["hops"], r[f"T{lengths[0]}"]["mean"], r[f"T{lengths[0]}"]["sem"])
                for r in records
                if r["method"] == method
            ],
            [(k, *v) for (m, k), v in paper.items() if m == paper_name],
        )
        for method, (paper_name, lengths) in METHODS.items()
    }
    plot_beside_paper(
        curves,
        path,
        "receptive field / horizon K",
        "episode reward (mean +- SEM)",
        f"{task.capitalize()}, 4 robots, windows of the paper's map, T = 50",
    )


def run(config: ReproduceConfig) -> None:
    """Plays the missing (method, K) results, prints the table, draws the plot."""
    out = Path(config.out)
    if not config.table_only:
        for method in config.methods:
            for hops in config.hops:
                path = out / f"{method}_K{hops}.json"
                if path.exists():
                    continue
                if method.startswith("gnn_") and not gnn_path(method, hops, config).exists():
                    print(f"skip {method} K={hops}: no {gnn_path(method, hops, config)}")
                    continue
                write_text_atomic(path, json.dumps(play(method, hops, config), indent=2))
                print(f"done {method} K={hops}", flush=True)
    records = [read_json(p) for p in sorted(out.glob("*_K*.json"))]
    records = [r for r in records if r.get("task", "coverage") == config.task]
    print_table(records, config.task)
    if records:
        plot(records, out / f"{config.task}.png", config.task)
        print(f"wrote {out / f'{config.task}.png'}")


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover reproduce-paper") -> None:
    """``marl-cover reproduce-paper``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    run(parse(ReproduceConfig, args, prog=prog, description=__doc__ or ""))
