"""The paper's published numbers, shipped with the package (``paper_results.csv``).

Tolstaya et al. publish the mean and standard deviation of the episode reward over 100 episodes
behind each figure: the receptive-field sweeps on the ~228-waypoint windows (``coverage``,
``exploration``) and the 10..100-robot runs on the 5659-waypoint map (``*_generalize_5659``).
Methods: ``greedy``, ``expert_receding_horizon``, ``gnn_linear_bc``, ``gnn_nonlinear_bc`` and
``gnn_linear_ppo``. Figures the paper gives only in its text are :data:`PAPER_TEXT`.
"""

from __future__ import annotations

import csv
from importlib import resources
from pathlib import Path

from marl_cover.errors import BadFileError, MissingFileError

#: The shipped table of the paper's figures.
PAPER_CSV = Path(str(resources.files("marl_cover.agents.evaluation") / "paper_results.csv"))
#: Figures of the paper's text: ``{name: (mean, sem)}``.
PAPER_TEXT: dict[str, tuple[float, float]] = {
    "coverage_open_loop_expert": (91.0, 0.87),
    "coverage_greedy_unlimited_horizon": (70.1, 1.32),
    "mission_greedy_points": (490.0, float("nan")),
    "mission_gnn_points": (610.0, float("nan")),
}
TASKS = ("coverage", "exploration", "coverage_generalize_5659", "exploration_generalize_5659")


def paper_numbers(task: str, path: Path = PAPER_CSV) -> dict[tuple[str, int], tuple[float, float]]:
    """``{(paper method, x): (mean, sem)}`` of one task (SEM = std / sqrt(episodes)).

    ``x`` is the receptive field K for ``"coverage"``/``"exploration"`` and the team size for
    the ``*_generalize_5659`` tasks.

    Raises:
        ValueError: an unknown task, naming the tasks.
        MissingFileError: the table is missing from this installation, naming its path.
        BadFileError: the table is damaged, naming it.
    """
    if task not in TASKS:
        raise ValueError(f"the paper has no figures for task {task!r}; tasks: {list(TASKS)}")
    if not path.is_file():
        raise MissingFileError(path, "the paper's figures are missing from this installation")
    try:
        with path.open(newline="") as handle:
            return {
                (row["method"], int(row["x"])): (
                    float(row["mean_reward"]),
                    float(row["std_reward"]) / float(row["episodes"]) ** 0.5,
                )
                for row in csv.DictReader(handle)
                if row["task"] == task
            }
    except (KeyError, TypeError, ValueError, UnicodeDecodeError, ZeroDivisionError) as error:
        raise BadFileError(path, f"not the paper's table of figures ({error!r})") from None
