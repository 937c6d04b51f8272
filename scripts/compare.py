"""Paired comparison of evaluation CSVs (``scripts/evaluate.py`` writes one row per seed).

    python scripts/compare.py outputs/eval/greedy_coverage.csv outputs/eval/gnn.csv
    python scripts/compare.py BASE.csv A.csv B.csv --out outputs/eval/compare.json
    python scripts/compare.py outputs/mission/mission.json:greedy outputs/mission/mission.json
    python scripts/compare.py outputs/mission/mission.json outputs/mission_other/mission.json

A ``.json`` file is a quadrotor mission table (``scripts/run_mission.py``'s ``mission.json``);
``FILE.json:METHOD`` picks its method (``gnn`` by default).

Every further file is compared with the first (the baseline) on the same seeds: its mean +-
SEM, the mean +- SEM of the per-seed differences, the ratio of the means, the mean +- SEM of the
per-seed ratios (the mission's figure) and the seeds won and lost. Files evaluated on different
seeds are an error that names them. ``--out`` writes the table as JSON (atomically).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.cli import write_text_atomic  # noqa: E402
from agents.comparison import compare, read_run  # noqa: E402


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("base", help="the baseline: an evaluation CSV or FILE.json[:METHOD]")
    parser.add_argument("others", nargs="+", help="runs compared with the baseline (same forms)")
    parser.add_argument("--out", type=Path, default=None, help="write the table as JSON")
    args = parser.parse_args(argv)
    try:
        base = read_run(args.base)
        rows = [compare(base, read_run(p), args.base, p) for p in args.others]
    except (OSError, ValueError) as error:
        sys.exit(f"compare.py: {error}")
    print(f"baseline {args.base}: {rows[0].base_mean:.2f} +- {rows[0].base_sem:.2f}")
    header = ("run", "seeds", "mean +- SEM", "paired diff", "ratio", "seed ratio", "W/L")
    print("{:48s} {:>5s} {:>15s} {:>16s} {:>7s} {:>16s} {:>7s}".format(*header))
    for row in rows:
        print(
            f"{row.other[-48:]:48s} {row.episodes:5d} "
            f"{row.other_mean:7.2f} +- {row.other_sem:4.2f} "
            f"{row.difference:+7.2f} +- {row.difference_sem:4.2f} {row.ratio:7.3f} "
            f"{row.seed_ratio:7.3f} +- {row.seed_ratio_sem:5.3f} "
            f"{row.wins:3d}/{row.losses:<3d}"
        )
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(args.out, json.dumps([r.as_dict() for r in rows], indent=1))
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
