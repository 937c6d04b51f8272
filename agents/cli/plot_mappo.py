"""Learning curves of MAPPO runs beside the paper's K = 19 coverage numbers (PNG and table).

Each run folder holds the ``curve.json`` that ``marl-cover train-mappo`` writes. The plot shows,
against robot observations (env steps x robots), the argmax policy's mean reward on the run's
evaluation seeds and the mean reward of the sampled episodes that ended in each batch; dashed
lines are the paper's linear PPO, linear BC and non-linear BC at K = 19, and any ``lines``.

Example::

    marl-cover plot-mappo runs=[outputs/mappo/linear_k19] out=outputs/mappo/curves.png
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from marl_cover.agents.cli.options import parse
from marl_cover.agents.evaluation.paper import paper_numbers
from marl_cover.agents.io import read_json

PAPER_METHODS = {
    "gnn_linear_ppo": "paper: linear PPO",
    "gnn_linear_bc": "paper: linear BC",
    "gnn_nonlinear_bc": "paper: non-linear BC",
}


@dataclass
class PlotConfig:
    """The runs and the reference lines."""

    runs: list[str] = field(default_factory=list)  # run folders (out= of train-mappo)
    lines: dict[str, float] = field(default_factory=dict)  # more reference lines: name -> reward
    out: str = "outputs/mappo/curves.png"  # the plot


def paper_lines() -> dict[str, float]:
    """The paper's K = 19 coverage rewards of :data:`PAPER_METHODS`."""
    numbers = paper_numbers("coverage")
    return {label: numbers[(method, 19)][0] for method, label in PAPER_METHODS.items()}


def run(config: PlotConfig) -> None:
    """Prints each run's last and best evaluation and draws the curves."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not config.runs:
        raise SystemExit("marl-cover plot-mappo: runs= names no run folder")
    figure, axis = plt.subplots(figsize=(8, 5))
    print(f"{'run':<40} {'iters':>6} {'observations':>13} {'last eval':>10} {'best eval':>10}")
    for index, folder in enumerate(map(Path, config.runs)):
        path = folder / "curve.json"
        if not path.is_file():
            raise SystemExit(f"marl-cover plot-mappo: no curve.json in {folder}")
        curve = read_json(path)
        color = f"C{index}"
        sampled = [(r["observations"], r["episode_reward"]) for r in curve if "episode_reward" in r]
        evaluated = [(r["observations"], r["eval_reward"]) for r in curve if "eval_reward" in r]
        if sampled:
            x, y = zip(*sampled, strict=True)
            axis.plot(x, y, color=color, alpha=0.35, lw=1)
        if evaluated:
            x, y = zip(*evaluated, strict=True)
            axis.plot(x, y, color=color, marker="o", ms=3, label=f"{folder.name} (argmax)")
        last = evaluated[-1][1] if evaluated else float("nan")
        best = max((y for _, y in evaluated), default=float("nan"))
        print(
            f"{folder.name:<40} {curve[-1]['iteration']:>6} {curve[-1]['observations']:>13.0f} "
            f"{last:>10.2f} {best:>10.2f}"
        )
    references = {**paper_lines(), **config.lines}
    for index, (name, value) in enumerate(references.items()):
        color = f"C{index + len(config.runs)}"
        axis.axhline(value, color=color, ls="--", lw=1, label=f"{name} {value:g}")
    axis.set_xlabel("robot observations (env steps x robots)")
    axis.set_ylabel("episode reward (points of interest visited)")
    axis.set_title("MAPPO on the paper's windows, 4 robots, T = 50 (faint: sampled episodes)")
    axis.grid(alpha=0.3)
    axis.legend(fontsize=8, loc="lower right")
    out = Path(config.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.tight_layout()
    figure.savefig(out, dpi=120)
    print(f"wrote {out}")


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover plot-mappo") -> None:
    """``marl-cover plot-mappo``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    run(parse(PlotConfig, args, prog=prog, description=__doc__ or ""))
