"""Greedy sweep of the paper's Fig. "coverage": ours beside the paper's CSV, and a plot.

Runs greedy for K = 3, 5, ..., 19 on 100 seeded windows of the paper's map (4 robots), with
T = 50 actions (ours) and T = 49 (what the paper's code ran), and prints each mean +- SEM beside
``shared/reference/paper_results.csv``. Writes JSON and a PNG of mean +- SEM against K.

    python scripts/reproduce_paper.py [--episodes 100] [--out outputs/reproduce_paper]
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.cli import write_text_atomic  # noqa: E402
from agents.evaluation import evaluate  # noqa: E402
from agents.greedy import GreedyPolicy  # noqa: E402
from marl_cover import parallel_env  # noqa: E402

HOPS = list(range(3, 20, 2))
PAPER_CSV = (
    Path(__file__).resolve().parent.parent.parent / "shared" / "reference" / "paper_results.csv"
)


def paper_numbers(path: Path, task: str, method: str) -> dict[int, tuple[float, float]]:
    """``{K: (mean, sem)}`` from the paper's CSV (SEM = std / sqrt(episodes))."""
    if not path.is_file():
        return {}
    with path.open() as handle:
        return {
            int(row["x"]): (
                float(row["mean_reward"]),
                float(row["std_reward"]) / float(row["episodes"]) ** 0.5,
            )
            for row in csv.DictReader(handle)
            if row["task"] == task and row["method"] == method
        }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0, help="first episode seed")
    parser.add_argument("--out", type=Path, default=Path("outputs/reproduce_paper"))
    args = parser.parse_args()
    seeds = range(args.seed, args.seed + args.episodes)
    paper = paper_numbers(PAPER_CSV, "coverage", "greedy")
    rows = []
    print(
        f"greedy, 4 robots, paper windows, {args.episodes} episodes "
        f"(seeds {seeds.start}..{seeds.stop - 1})"
    )
    print(f"{'K':>3} {'ours T=50':>14} {'ours T=49':>14} {'paper (T=49)':>14}")
    for hops in HOPS:
        row = {"hops": hops}
        for steps in (50, 49):
            env = parallel_env(map="paper", hops=hops, max_steps=steps)
            summary = evaluate(env, GreedyPolicy(hops, fallback="random"), seeds)
            row[f"T{steps}"] = {"mean": summary.mean, "std": summary.std, "sem": summary.sem}
        if hops in paper:
            row["paper"] = {"mean": paper[hops][0], "sem": paper[hops][1]}
        rows.append(row)
        cells = [
            f"{row[k]['mean']:6.1f} +- {row[k]['sem']:4.2f}" if k in row else f"{'-':>14}"
            for k in ("T50", "T49", "paper")
        ]
        print(f"{hops:>3} " + " ".join(f"{c:>14}" for c in cells), flush=True)
    write_text_atomic(args.out / "greedy_coverage.json", json.dumps(rows, indent=2))
    plot(rows, args.out / "greedy_coverage.png")
    print(f"wrote {args.out}/greedy_coverage.json and .png")


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4), dpi=120)
    for key, label, style in (
        ("T50", "greedy, ours (T=50)", "o-"),
        ("T49", "greedy, ours (T=49)", "s-"),
        ("paper", "greedy, paper", "k^--"),
    ):
        points = [(r["hops"], r[key]["mean"], r[key]["sem"]) for r in rows if key in r]
        if points:
            x, y, e = zip(*points, strict=True)
            ax.errorbar(x, y, yerr=e, fmt=style, capsize=3, label=label)
    ax.set_xlabel("receptive field / horizon K")
    ax.set_ylabel("episode reward (mean +- SEM)")
    ax.set_title("Coverage, 4 robots, windows of the paper's map")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


if __name__ == "__main__":
    main()
