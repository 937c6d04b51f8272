"""The paper's published numbers (``shared/reference/paper_results.csv``), for tables and plots."""

from __future__ import annotations

import csv
from pathlib import Path

#: Where the reference figures live beside the repository (absent: tables show no paper column).
PAPER_CSV = (
    Path(__file__).resolve().parent.parent.parent / "shared" / "reference" / ("paper_results.csv")
)


def paper_numbers(task: str, path: Path = PAPER_CSV) -> dict[tuple[str, int], tuple[float, float]]:
    """``{(paper method, x): (mean, sem)}`` of one task (SEM = std / sqrt(episodes)).

    ``x`` is the receptive field K for ``"coverage"``/``"exploration"`` and the team size for
    the ``*_generalize_5659`` tasks; an empty dict when the file is absent.
    """
    if not path.is_file():
        return {}
    with path.open() as handle:
        return {
            (row["method"], int(row["x"])): (
                float(row["mean_reward"]),
                float(row["std_reward"]) / float(row["episodes"]) ** 0.5,
            )
            for row in csv.DictReader(handle)
            if row["task"] == task
        }
