"""Learning curves of MAPPO runs beside the paper's K = 19 coverage numbers (PNG + table).

    python scripts/plot_mappo.py outputs/mappo/linear_k19 outputs/mappo/finetune_nonlinear_k19 \\
        --line "our BC, non-linear=79.8" --out outputs/mappo/curves.png

Each run folder holds the ``curve.json`` that ``scripts/train_mappo.py`` writes. The plot shows,
against robot observations (env steps x robots), the argmax policy's mean reward on the run's
evaluation seeds and the mean reward of the sampled episodes that ended in each batch; dashed
lines are the paper's linear PPO, linear BC and non-linear BC at K = 19
(``../shared/reference/paper_results.csv``) and any ``--line name=value``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.paper import paper_numbers  # noqa: E402

PAPER_METHODS = {
    "gnn_linear_ppo": "paper: linear PPO",
    "gnn_linear_bc": "paper: linear BC",
    "gnn_nonlinear_bc": "paper: non-linear BC",
}


def paper_lines() -> dict[str, float]:
    """The paper's K = 19 coverage rewards of :data:`PAPER_METHODS` (empty without the file)."""
    numbers = paper_numbers("coverage")
    return {
        label: numbers[(method, 19)][0]
        for method, label in PAPER_METHODS.items()
        if (method, 19) in numbers
    }


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="run folders (out= of train_mappo)")
    parser.add_argument("--line", action="append", default=[], help="name=value reference line")
    parser.add_argument("--out", type=Path, default=Path("outputs/mappo/curves.png"))
    args = parser.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(8, 5))
    print(f"{'run':<40} {'iters':>6} {'observations':>13} {'last eval':>10} {'best eval':>10}")
    for index, run in enumerate(args.runs):
        path = run / "curve.json"
        if not path.is_file():
            raise SystemExit(f"plot_mappo: no curve.json in {run} (is it a train_mappo out=?)")
        curve = json.loads(path.read_text())
        color = f"C{index}"
        observations = [row["observations"] for row in curve if "episode_reward" in row]
        sampled = [row["episode_reward"] for row in curve if "episode_reward" in row]
        evaluated = [
            (row["observations"], row["eval_reward"]) for row in curve if "eval_reward" in row
        ]
        axis.plot(observations, sampled, color=color, alpha=0.35, lw=1)
        if evaluated:
            x, y = zip(*evaluated, strict=True)
            axis.plot(x, y, color=color, marker="o", ms=3, label=f"{run.name} (argmax, eval seeds)")
        last = evaluated[-1][1] if evaluated else float("nan")
        best = max((y for _, y in evaluated), default=float("nan"))
        print(
            f"{run.name:<40} {curve[-1]['iteration']:>6} {curve[-1]['observations']:>13.0f} "
            f"{last:>10.2f} {best:>10.2f}"
        )
    references = paper_lines()
    for item in args.line:
        name, _, value = item.partition("=")
        try:
            references[name] = float(value)
        except ValueError:
            parser.error(f"--line takes name=number, got {item!r}")
    for index, (name, value) in enumerate(references.items()):
        axis.axhline(
            value, color=f"C{index + len(args.runs)}", ls="--", lw=1, label=f"{name} {value:g}"
        )
    axis.set_xlabel("robot observations (env steps x robots)")
    axis.set_ylabel("episode reward (points of interest visited)")
    axis.set_title("MAPPO on the paper's windows, 4 robots, T = 50 (faint: sampled episodes)")
    axis.grid(alpha=0.3)
    axis.legend(fontsize=8, loc="lower right")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    figure.tight_layout()
    figure.savefig(args.out, dpi=120)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main(sys.argv[1:])
