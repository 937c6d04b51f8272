"""Figures of our results beside the paper's: mean +- SEM against a setting (K, team size)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

#: ``(x, mean, sem)`` points of one curve.
Points = Sequence[tuple[float, ...]]


def plot_beside_paper(
    curves: Mapping[str, tuple[Points, Points]],
    path: Path,
    xlabel: str,
    ylabel: str,
    title: str,
) -> None:
    """Writes a PNG of each method's points, ours solid and the paper's dashed in one colour.

    Args:
        curves: Method label -> (our points, the paper's points); either may be empty.
        path: The PNG to write (its folder is made).
        xlabel, ylabel, title: The axes' labels and the title.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5), dpi=120)
    for index, (label, (ours, paper)) in enumerate(curves.items()):
        colour = f"C{index}"
        for points, style, alpha, who in ((ours, "o-", 1.0, "ours"), (paper, "^--", 0.5, "paper")):
            if points:
                x, y, e = zip(*sorted(points), strict=True)
                ax.errorbar(
                    x,
                    y,
                    yerr=e,
                    fmt=style,
                    color=colour,
                    alpha=alpha,
                    capsize=3,
                    label=f"{label}, {who}",
                )
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
