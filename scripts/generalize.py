"""The paper's Fig. "generalize": 10 to 100 robots on the 5659-waypoint map, GNN beside greedy.

The GNN was trained with 4 robots on ~228-waypoint windows; here it runs on the paper's large
map (T = 50, K = the model's receptive field) in one centralized pass per step (the same actions
as each robot on its own ego-graph, tested). Greedy runs on each robot's ego-graph. Seeds are
paired across methods. Each (method, team size) result is written to
``OUT/<method>_R<robots>.json`` when done, with its setup (task, seeds, the model's SHA-256),
and read back when present (resumable); a file made under another setup is an error.

    python scripts/generalize.py [--task coverage|exploration] [--robots 10 20 30 40 50 100]
        [--episodes 100] [--checkpoint agents/models/shipped/<task>_gnn.pt]
        [--out outputs/generalize]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.cli import file_sha256, non_negative_int, positive_int, read_result, write_text_atomic  # noqa: E402
from agents.evaluation import evaluate  # noqa: E402
from agents.greedy import GreedyPolicy  # noqa: E402
from agents.paper import paper_numbers  # noqa: E402
from marl_cover import parallel_env  # noqa: E402
from marl_cover.config import TASKS  # noqa: E402

TEAMS = [10, 20, 30, 40, 50, 100]
PAPER_METHODS = {"greedy": "greedy", "gnn": "gnn_nonlinear_bc"}


def setup(method: str, robots: int, args: argparse.Namespace) -> dict:
    """What decides one (method, team size) result: a file made under another is not reused."""
    return {
        "method": method,
        "task": args.task,
        "robots": robots,
        "episodes": args.episodes,
        "seed": args.seed,
        "model_sha256": args.model_sha256 if method == "gnn" else None,
    }


def run(method: str, robots: int, args: argparse.Namespace, model) -> dict:  # noqa: ANN001
    hops = model.config.hops
    env = parallel_env(
        map="paper_large", num_robots=robots, hops=hops, max_steps=50, task=args.task
    )
    policy: Any
    if method == "gnn":
        from agents.models.policy import GNNPolicy

        policy = GNNPolicy(model, centralized=True)
    else:
        policy = GreedyPolicy(hops, fallback="random")
    seeds = range(args.seed, args.seed + args.episodes)
    summary = evaluate(env, policy, seeds)
    return {
        "method": method,
        "task": args.task,
        "robots": robots,
        "hops": hops,
        "episodes": args.episodes,
        "seed": args.seed,
        "checkpoint": str(args.checkpoint) if method == "gnn" else None,
        "mean": summary.mean,
        "std": summary.std,
        "sem": summary.sem,
        "rewards": [r.reward for r in summary.results],
        "controller_ms_per_step": summary.controller_ms_per_step,
        "setup": setup(method, robots, args),
    }


def main() -> None:
    import torch

    from agents.models.policy import load_model
    from agents.models.shipped import shipped_model_path

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", choices=TASKS, default="coverage")
    parser.add_argument("--robots", nargs="+", type=positive_int, default=TEAMS)
    parser.add_argument("--episodes", type=positive_int, default=100)
    parser.add_argument("--seed", type=non_negative_int, default=0)
    parser.add_argument("--checkpoint", type=Path, default=None)
    parser.add_argument("--out", type=Path, default=Path("outputs/generalize"))
    parser.add_argument(
        "--methods", nargs="+", default=["greedy", "gnn"], choices=["greedy", "gnn"]
    )
    parser.add_argument("--table-only", action="store_true")
    args = parser.parse_args()
    torch.set_num_threads(1)
    args.checkpoint = args.checkpoint or shipped_model_path(args.task)
    try:
        model, _ = load_model(args.checkpoint)
    except (FileNotFoundError, ValueError) as error:
        parser.error(str(error))
    args.model_sha256 = file_sha256(args.checkpoint)  # names the model in each result's setup
    if not args.table_only:
        for robots in args.robots:
            for method in args.methods:
                path = args.out / f"{method}_R{robots}.json"
                if path.exists():
                    read_result(path, setup(method, robots, args))
                else:
                    write_text_atomic(path, json.dumps(run(method, robots, args, model), indent=2))
                    print(f"done {method} R={robots}", flush=True)
    records = {
        (r["method"], r["robots"]): r
        for r in (json.loads(p.read_text()) for p in sorted(args.out.glob("*_R*.json")))
    }
    paper = paper_numbers(f"{args.task}_generalize_5659")
    print(
        f"{'R':>4} {'greedy ours':>16} {'GNN ours':>16} {'ratio (paired)':>18} "
        f"{'greedy paper':>16} {'GNN paper':>16}"
    )
    for robots in sorted({k[1] for k in records}):
        greedy, gnn = records.get(("greedy", robots)), records.get(("gnn", robots))
        cells = [f"{r['mean']:7.1f} +- {r['sem']:4.1f}" if r else "-" for r in (greedy, gnn)]
        ratio = "-"
        if greedy and gnn and len(greedy["rewards"]) == len(gnn["rewards"]):
            import numpy as np

            ratios = np.array(gnn["rewards"]) / np.maximum(np.array(greedy["rewards"]), 1)
            ratio = f"{gnn['mean'] / greedy['mean']:5.3f} ({np.median(ratios):.3f} med)"
        for name in ("greedy", "gnn"):
            value = paper.get((PAPER_METHODS[name], robots))
            cells.append(f"{value[0]:7.1f} +- {value[1]:4.1f}" if value else "-")
        print(
            f"{robots:>4} {cells[0]:>16} {cells[1]:>16} {ratio:>18} {cells[2]:>16} {cells[3]:>16}"
        )
    if records:
        plot(records, paper, args.out / "generalize.png", args.task)
        print(f"wrote {args.out / 'generalize.png'}")


def plot(records: dict, paper: dict, path: Path, task: str) -> None:
    """Mean +- SEM against team size, ours (solid) and the paper's (dashed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.2), dpi=120)
    for colour, method in zip("br", ("greedy", "gnn"), strict=True):
        ours = sorted((k[1], r["mean"], r["sem"]) for k, r in records.items() if k[0] == method)
        if ours:
            x, y, e = zip(*ours, strict=True)
            ax.errorbar(x, y, yerr=e, fmt="o-", color=colour, capsize=3, label=f"{method}, ours")
        ref = sorted((k[1], *v) for k, v in paper.items() if k[0] == PAPER_METHODS[method])
        if ref:
            x, y, e = zip(*ref, strict=True)
            label = f"{PAPER_METHODS[method]}, paper"
            ax.errorbar(x, y, yerr=e, fmt="^--", color=colour, alpha=0.5, capsize=3, label=label)
    ax.set_xlabel("robots")
    ax.set_ylabel("points of interest visited in 50 steps (mean +- SEM)")
    ax.set_title(f"{task.capitalize()} on the 5659-waypoint map, K = 19")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


if __name__ == "__main__":
    main()
