"""Paired comparisons of evaluation runs: per-seed differences of two methods' rewards.

``marl-cover evaluate`` (and ``generalize``) write one row per episode seed, and ``marl-cover
mission`` one total per seed and method in its ``mission.json``. Two methods evaluated on the
same seeds saw the same maps, starts and points of interest, so the SEM of their per-seed
differences is far smaller than either method's own SEM; this is the figure the results quote
as "paired +d +- s". The statistics are scipy's (``scipy.stats.sem``, the paired t-test
``ttest_rel`` and the Wilcoxon signed-rank test).
"""

from __future__ import annotations

import csv
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from marl_cover.agents.io import read_json
from marl_cover.errors import BadFileError, MissingFileError


def sem(values: np.ndarray) -> float:
    """Standard error of the mean (``scipy.stats.sem``, ddof 1); 0 for fewer than two values."""
    return float(stats.sem(values)) if len(values) > 1 else 0.0


def paired_pvalues(base: np.ndarray, other: np.ndarray) -> tuple[float, float]:
    """Two-sided p-values of the paired t-test and of the Wilcoxon signed-rank test (NaN where
    undefined: fewer than two seeds, or no seed that differs)."""
    diff = other - base
    if len(diff) < 2 or not np.any(diff):
        return math.nan, math.nan
    t_test = float(stats.ttest_rel(other, base).pvalue)
    return t_test, float(stats.wilcoxon(other, base).pvalue)


@dataclass(frozen=True)
class PairedComparison:
    """``other`` against ``base`` over the seeds both were evaluated on.

    Attributes:
        base: Name of the baseline run.
        other: Name of the compared run.
        episodes: Number of paired seeds.
        base_mean: Mean reward of the baseline (its SEM in ``base_sem``).
        other_mean: Mean reward of the compared run (its SEM in ``other_sem``).
        difference: Mean of the per-seed differences ``other - base``.
        difference_sem: SEM of the per-seed differences.
        ratio: ``other_mean / base_mean`` (the ratio of the means; NaN if ``base_mean`` is 0).
        seed_ratio: Mean of the per-seed ratios ``other / base`` (the quadrotor mission's
            figure; NaN if a baseline reward is 0), its SEM in ``seed_ratio_sem``.
        wins: Seeds where ``other`` scored more than ``base`` (``losses``: less).
        t_pvalue: Two-sided p-value of the paired t-test (``scipy.stats.ttest_rel``).
        wilcoxon_pvalue: Two-sided p-value of the Wilcoxon signed-rank test.
    """

    base: str
    other: str
    episodes: int
    base_mean: float
    base_sem: float
    other_mean: float
    other_sem: float
    difference: float
    difference_sem: float
    ratio: float
    seed_ratio: float
    seed_ratio_sem: float
    wins: int
    losses: int
    t_pvalue: float = math.nan
    wilcoxon_pvalue: float = math.nan

    def as_dict(self) -> dict[str, Any]:
        """Plain types, for JSON."""
        return asdict(self)


def read_rewards(path: str | Path) -> dict[int, float]:
    """Reward per seed from an evaluation CSV (columns ``seed`` and ``reward``).

    Raises:
        MissingFileError: no such file.
        BadFileError: the file is not text, a column is missing, a value is not a number, or a
            seed repeats (the message names the file and the row).
    """
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(path, "no evaluation CSV here")
    try:
        with path.open(newline="") as handle:
            return _rewards_of_rows(path, csv.DictReader(handle))
    except UnicodeDecodeError:
        raise BadFileError(
            path, "not a text file (an evaluation CSV, written by marl-cover evaluate)"
        ) from None


def _rewards_of_rows(path: Path, reader: csv.DictReader) -> dict[int, float]:
    """The reward per seed of an open evaluation CSV (see :func:`read_rewards`)."""
    missing = {"seed", "reward"} - set(reader.fieldnames or ())
    if missing:
        raise BadFileError(path, f"no column {sorted(missing)} (has {reader.fieldnames})")
    rewards: dict[int, float] = {}
    for row_number, row in enumerate(reader, start=2):
        try:
            seed, reward = int(row["seed"]), float(row["reward"])
        except (TypeError, ValueError):
            raise BadFileError(
                path,
                f"line {row_number}: seed {row['seed']!r} / reward {row['reward']!r} is not "
                "a number",
            ) from None
        if seed in rewards:
            raise BadFileError(path, f"line {row_number}: seed {seed} appears twice")
        rewards[seed] = reward
    if not rewards:
        raise BadFileError(path, "no episodes")
    return rewards


def read_mission_totals(path: str | Path, method: str = "gnn") -> dict[int, float]:
    """Points visited per seed by one method of a ``marl-cover mission`` table (``mission.json``).

    Raises:
        MissingFileError: no such file.
        BadFileError: the file is not a mission table or has no such method (the message names
            the file and the methods it has).
    """
    path = Path(path)
    table = read_json(path)
    try:
        seeds, methods = table["seeds"], table["methods"]
    except (KeyError, TypeError):
        raise BadFileError(
            path,
            "not a mission table (marl-cover mission's mission.json, with 'seeds' and 'methods')",
        ) from None
    if method not in methods or "totals" not in methods[method]:
        raise BadFileError(path, f"no method {method!r} with totals (has {sorted(methods)})")
    totals = methods[method]["totals"]
    if len(totals) != len(seeds):
        raise BadFileError(path, f"{len(seeds)} seeds but {len(totals)} totals for {method!r}")
    return {int(seed): float(total) for seed, total in zip(seeds, totals, strict=True)}


def read_run(spec: str | Path) -> dict[int, float]:
    """Reward per seed of a run named on the command line.

    ``FILE.csv``: an evaluation CSV (:func:`read_rewards`); ``FILE.json`` or
    ``FILE.json:METHOD``: a mission table's method (:func:`read_mission_totals`, ``gnn`` by
    default), e.g. ``outputs/mission/mission.json:greedy``.
    """
    text = str(spec)
    head, sep, method = text.rpartition(":")
    if sep and head.endswith(".json"):
        return read_mission_totals(head, method)
    if text.endswith(".json"):
        return read_mission_totals(text)
    return read_rewards(text)


def compare(
    base: dict[int, float],
    other: dict[int, float],
    base_name: str = "base",
    other_name: str = "other",
) -> PairedComparison:
    """Pairs two runs seed by seed.

    Args:
        base: Reward per seed of the baseline.
        other: Reward per seed of the compared run.
        base_name: Name of the baseline in messages and in the result.
        other_name: Name of the compared run.

    Raises:
        ValueError: the two runs were not evaluated on the same seeds (the message lists the
            seeds only one of them has).
    """
    if set(base) != set(other):
        only_base = sorted(set(base) - set(other))
        only_other = sorted(set(other) - set(base))
        raise ValueError(
            f"{base_name} and {other_name} are not paired: seeds only in {base_name} "
            f"{_head(only_base)}, only in {other_name} {_head(only_other)}"
        )
    seeds = sorted(base)
    a = np.array([base[s] for s in seeds], dtype=np.float64)  # (episodes,)
    b = np.array([other[s] for s in seeds], dtype=np.float64)  # (episodes,)
    diff = b - a  # (episodes,)
    ratios = np.where(a != 0, b / np.where(a != 0, a, 1.0), math.nan)  # (episodes,)
    base_mean, other_mean = float(a.mean()), float(b.mean())
    t_pvalue, wilcoxon_pvalue = paired_pvalues(a, b)
    return PairedComparison(
        base=base_name,
        other=other_name,
        episodes=len(seeds),
        base_mean=base_mean,
        base_sem=sem(a),
        other_mean=other_mean,
        other_sem=sem(b),
        difference=float(diff.mean()),
        difference_sem=sem(diff),
        ratio=other_mean / base_mean if base_mean != 0 else math.nan,
        seed_ratio=float(ratios.mean()),
        seed_ratio_sem=sem(ratios),
        wins=int((diff > 0).sum()),
        losses=int((diff < 0).sum()),
        t_pvalue=t_pvalue,
        wilcoxon_pvalue=wilcoxon_pvalue,
    )


def _head(seeds: list[int], limit: int = 8) -> str:
    text = ", ".join(str(s) for s in seeds[:limit])
    return f"[{text}{', ...' if len(seeds) > limit else ''}] ({len(seeds)})"
