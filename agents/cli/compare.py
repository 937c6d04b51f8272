"""Paired comparison of evaluation CSVs (``marl-cover evaluate`` writes one row per seed).

Every further run is compared with the first (the baseline) on the same seeds: its mean +- SEM,
the mean +- SEM of the per-seed differences, the ratio of the means, the mean +- SEM of the
per-seed ratios (the mission's figure), the seeds won and lost, and the p-values of the paired
t-test and the Wilcoxon signed-rank test. A ``.json`` run is a quadrotor mission table
(``marl-cover mission``'s ``mission.json``); ``FILE.json:METHOD`` picks its method (``gnn`` by
default). Runs evaluated on different seeds are an error that names them.

Examples::

    marl-cover compare --runs outputs/greedy.csv outputs/gnn.csv
    marl-cover compare --runs outputs/mission/mission.json:greedy outputs/mission/mission.json
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from marl_cover.agents.cli.options import parse
from marl_cover.agents.evaluation.comparison import PairedComparison, compare, read_run
from marl_cover.agents.io import write_text_atomic


@dataclass
class CompareConfig:
    """The runs to pair."""

    runs: list[str] = field(default_factory=list)  # the baseline, then the runs compared with it
    out: str | None = None  # write the table as JSON here


def run(config: CompareConfig) -> list[PairedComparison]:
    """Prints the table (and writes it with ``out``).

    Raises:
        SystemExit: fewer than two runs, a file that cannot be read, or runs on other seeds.
    """
    if len(config.runs) < 2:
        raise SystemExit(f"marl-cover compare: runs: a baseline and a run, got {config.runs}")
    base_name, *others = config.runs
    try:
        base = read_run(base_name)
        rows = [compare(base, read_run(p), base_name, p) for p in others]
    except (OSError, ValueError) as error:
        raise SystemExit(f"marl-cover compare: {error}") from None
    print(f"baseline {base_name}: {rows[0].base_mean:.2f} +- {rows[0].base_sem:.2f}")
    header = ("run", "seeds", "mean +- SEM", "paired diff", "ratio", "seed ratio", "W/L", "p (t)")
    print("{:40s} {:>5s} {:>15s} {:>16s} {:>7s} {:>16s} {:>7s} {:>8s}".format(*header))
    for row in rows:
        print(
            f"{row.other[-40:]:40s} {row.episodes:5d} "
            f"{row.other_mean:7.2f} +- {row.other_sem:4.2f} "
            f"{row.difference:+7.2f} +- {row.difference_sem:4.2f} {row.ratio:7.3f} "
            f"{row.seed_ratio:7.3f} +- {row.seed_ratio_sem:5.3f} "
            f"{row.wins:3d}/{row.losses:<3d} {row.t_pvalue:8.2g}"
        )
    if config.out is not None:
        write_text_atomic(config.out, json.dumps([r.as_dict() for r in rows], indent=1))
        print(f"wrote {Path(config.out)}")
    return rows


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover compare") -> None:
    """``marl-cover compare``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    run(parse(CompareConfig, args, prog=prog, description=__doc__ or ""))
