"""The paper's sweeps (Figs. "coverage", "exploration"): greedy, the receding-horizon expert and
the GNNs against K.

Runs each method for K = 3, 5, ..., 19 on 100 seeded windows of the paper's map (4 robots,
T = 50; greedy also with T = 49, what the paper's code ran), prints mean +- SEM beside
``shared/reference/paper_results.csv`` and draws mean +- SEM against K to a PNG. The GNN rows
(``gnn_linear``, ``gnn_nonlinear``) evaluate ``MODELS/<kind>_k<K>/best.pt`` (decentralized,
argmax), as trained by ``scripts/train_bc.py``.

Each (method, K) result is written to ``OUT/<method>_K<k>.json`` as soon as it is done and is
skipped when present, so the sweep resumes after an interrupt and can be split over processes
(``--hops 3 5 7`` in one, ``--hops 9 11`` in another); ``--table-only`` prints and plots what
is there. ``--task exploration`` runs the exploration task (22 m sensor); there the expert is
the fair one (it plans only on what the team has discovered, frontier included).

    python scripts/reproduce_paper.py [--task coverage|exploration] [--methods greedy expert_rh]
        [--hops 3 5 ... 19]
        [--episodes 100] [--expert-time-limit 0.15] [--backend pyvrp] [--out outputs/paper]
    python scripts/reproduce_paper.py --methods gnn_linear gnn_nonlinear --models outputs/bc
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.cli import non_negative_int, positive_float, positive_int, write_text_atomic  # noqa: E402
from agents.evaluation import evaluate  # noqa: E402
from agents.greedy import GreedyPolicy  # noqa: E402
from agents.paper import paper_numbers  # noqa: E402
from marl_cover import parallel_env  # noqa: E402
from marl_cover.config import TASKS  # noqa: E402

HOPS = list(range(3, 20, 2))
#: Our method names -> the paper's, and the episode lengths each is run with.
METHODS = {
    "greedy": ("greedy", (50, 49)),
    "expert_rh": ("expert_receding_horizon", (50,)),
    "gnn_linear": ("gnn_linear_bc", (50,)),
    "gnn_nonlinear": ("gnn_nonlinear_bc", (50,)),
}


def model_path(method: str, hops: int, args: argparse.Namespace) -> Path:
    return args.models / f"{method.removeprefix('gnn_')}_k{hops}" / "best.pt"


def make_policy(method: str, hops: int, args: argparse.Namespace):  # noqa: ANN201
    if method == "greedy":
        return GreedyPolicy(hops, fallback="random")
    if method.startswith("gnn_"):
        import torch

        from agents.models.policy import GNNPolicy, load_model

        torch.set_num_threads(1)
        model, _ = load_model(model_path(method, hops, args))
        return GNNPolicy(model)
    from agents.experts import RoutingExpert

    return RoutingExpert(
        backend=args.backend,
        mode="receding",
        horizon=hops,
        time_limit=args.expert_time_limit,
        information="known" if args.task == "exploration" else "full",
    )


def run(method: str, hops: int, args: argparse.Namespace) -> dict:
    seeds = range(args.seed, args.seed + args.episodes)
    record: dict = {
        "task": args.task,
        "method": method,
        "hops": hops,
        "episodes": args.episodes,
        "seed": args.seed,
    }
    if method == "expert_rh":
        record["expert"] = {"backend": args.backend, "time_limit": args.expert_time_limit}
    if method.startswith("gnn_"):
        from agents.models.policy import load_model

        _, metadata = load_model(model_path(method, hops, args))
        record["model"] = {"path": str(model_path(method, hops, args)), **metadata}
    for steps in METHODS[method][1]:
        env = parallel_env(map="paper", hops=hops, max_steps=steps, task=args.task)
        summary = evaluate(env, make_policy(method, hops, args), seeds)
        record[f"T{steps}"] = {
            "mean": summary.mean,
            "std": summary.std,
            "sem": summary.sem,
            "controller_ms_per_step": summary.controller_ms_per_step,
            "counts": summary.policy_counts,
        }
    return record


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", choices=TASKS, default="coverage")
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS))
    parser.add_argument("--hops", nargs="+", type=positive_int, default=HOPS)
    parser.add_argument("--episodes", type=positive_int, default=100)
    parser.add_argument("--seed", type=non_negative_int, default=0, help="first episode seed")
    parser.add_argument("--backend", default="pyvrp", choices=["pyvrp", "ortools"])
    parser.add_argument("--expert-time-limit", type=positive_float, default=0.15)
    parser.add_argument("--out", type=Path, default=Path("outputs/paper"))
    parser.add_argument("--models", type=Path, default=Path("outputs/bc"), help="GNN runs")
    parser.add_argument("--table-only", action="store_true")
    args = parser.parse_args()
    if not args.table_only:
        for method in args.methods:
            for hops in args.hops:
                path = args.out / f"{method}_K{hops}.json"
                if path.exists():
                    continue
                if method.startswith("gnn_") and not model_path(method, hops, args).exists():
                    print(f"skip {method} K={hops}: no {model_path(method, hops, args)}")
                    continue
                write_text_atomic(path, json.dumps(run(method, hops, args), indent=2))
                print(f"done {method} K={hops}", flush=True)
    records = [json.loads(p.read_text()) for p in sorted(args.out.glob("*_K*.json"))]
    records = [r for r in records if r.get("task", "coverage") == args.task]
    print_table(records, args.task)
    if records:
        plot(records, args.out / f"{args.task}.png", args.task)
        print(f"wrote {args.out / f'{args.task}.png'}")


def print_table(records: list[dict], task: str) -> None:
    paper = paper_numbers(task)
    by_key = {(r["method"], r["hops"]): r for r in records}
    header = f"{'K':>3}"
    columns = []
    for method, (paper_name, lengths) in METHODS.items():
        for steps in lengths:
            columns.append((f"{method} T={steps}", method, f"T{steps}"))
        columns.append((f"paper {method}", paper_name, "paper"))
    print(header + "".join(f"{name:>20}" for name, *_ in columns))
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
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paper = paper_numbers(task)
    fig, ax = plt.subplots(figsize=(7, 4.5), dpi=120)
    for colour, (method, (paper_name, lengths)) in zip("brgm", METHODS.items(), strict=False):
        points = sorted(
            (r["hops"], r[f"T{lengths[0]}"]["mean"], r[f"T{lengths[0]}"]["sem"])
            for r in records
            if r["method"] == method
        )
        if points:
            x, y, e = zip(*points, strict=True)
            ax.errorbar(x, y, yerr=e, fmt="o-", color=colour, capsize=3, label=f"{method}, ours")
        ref = sorted((k, *v) for (m, k), v in paper.items() if m == paper_name)
        if ref:
            x, y, e = zip(*ref, strict=True)
            ax.errorbar(
                x,
                y,
                yerr=e,
                fmt="^--",
                color=colour,
                alpha=0.5,
                capsize=3,
                label=f"{method}, paper",
            )
    ax.set_xlabel("receptive field / horizon K")
    ax.set_ylabel("episode reward (mean +- SEM)")
    ax.set_title(f"{task.capitalize()}, 4 robots, windows of the paper's map, T = 50")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


if __name__ == "__main__":
    main()
