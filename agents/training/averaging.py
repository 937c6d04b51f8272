"""Choosing a weight average of a training run's snapshots on selection seeds.

A behaviour-cloning or MAPPO run with ``snapshots=true`` keeps the model of every validation
step or evaluated iteration (``RUN/steps/step_NNNNNN.pt``). The parameter-wise mean of the
last few of them (a stochastic weight average,
:func:`~marl_cover.agents.models.checkpoints.average_models`) often plays better than any one
snapshot. How many to average is chosen here the way the shipped models' windows were: each
candidate window, the last ``n`` snapshots for each ``n`` asked for, is averaged and played on
the same selection seeds, and the window with the highest mean reward wins. The test seeds are
not touched; run ``marl-cover evaluate`` on the chosen file for them.

Every window's rewards are written to ``cache/window_FIRST_LAST.json`` with the setup that made
them (the snapshot files' SHA-256, the environment, the seeds), so an interrupted selection
resumes where it stopped and a later call with more window sizes evaluates only the new ones; a
cached file of another setup is an error naming it (:func:`marl_cover.agents.io.read_result`).
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from marl_cover.agents.io import file_sha256, read_result, write_text_atomic

SNAPSHOT = re.compile(r"step_(\d+)\.pt")


@dataclass(frozen=True)
class WindowResult:
    """One candidate average, played on the selection seeds.

    Attributes:
        steps: Training steps of the averaged snapshots, in order.
        files: The snapshot files.
        rewards: Episode rewards, one per selection seed.
    """

    steps: list[int]
    files: list[str]
    rewards: list[float]

    @property
    def name(self) -> str:
        """``"steps 8000..16000 (9)"``."""
        return f"steps {self.steps[0]}..{self.steps[-1]} ({len(self.steps)})"

    @property
    def mean(self) -> float:
        """Mean reward over the seeds."""
        return float(np.mean(self.rewards))

    @property
    def sem(self) -> float:
        """Standard error of the mean reward over the seeds."""
        return float(np.std(self.rewards, ddof=1) / np.sqrt(len(self.rewards)))

    def paired(self, other: WindowResult) -> tuple[float, float]:
        """Mean and SEM of the per-seed differences ``self - other``."""
        diff = np.asarray(self.rewards) - np.asarray(other.rewards)
        return float(diff.mean()), float(diff.std(ddof=1) / np.sqrt(len(diff)))


def snapshot_files(folder: str | Path) -> list[tuple[int, Path]]:
    """The ``(step, file)`` snapshots of a run, by step.

    Args:
        folder: A run's ``steps/`` folder, or the run folder holding one.

    Raises:
        FileNotFoundError: no folder, or no ``step_NNNNNN.pt`` in it, naming it.
    """
    folder = Path(folder)
    if (folder / "steps").is_dir():
        folder = folder / "steps"
    if not folder.is_dir():
        raise FileNotFoundError(f"no snapshot folder at {folder}")
    found = sorted(
        (int(match.group(1)), path)
        for path in folder.iterdir()
        if (match := SNAPSHOT.fullmatch(path.name))
    )
    if not found:
        raise FileNotFoundError(
            f"no snapshots (step_NNNNNN.pt) in {folder}; train with snapshots=true"
        )
    return found


def trailing_windows(
    snapshots: Sequence[tuple[int, Path]], sizes: Iterable[int]
) -> list[list[tuple[int, Path]]]:
    """The last ``n`` snapshots for each ``n`` of ``sizes`` (largest window first, each once).

    Raises:
        ValueError: a size below 1 or above the number of snapshots.
    """
    windows = []
    for size in sorted(set(sizes), reverse=True):
        if not 1 <= size <= len(snapshots):
            raise ValueError(f"window size {size} is not in 1..{len(snapshots)} (the snapshots)")
        windows.append(list(snapshots[-size:]))
    return windows


def load_window(files: Sequence[str | Path]) -> tuple[Any, dict[str, Any]]:
    """The network of a window: the one file, or the mean of several."""
    from marl_cover.agents.models.checkpoints import average_models, load_model

    return load_model(files[0]) if len(files) == 1 else average_models(list(files))


def evaluate_window(
    window: Sequence[tuple[int, Path]],
    env_kwargs: dict[str, Any],
    seeds: Sequence[int],
    cache: Path,
    progress: Callable[[Iterable[int]], Iterable[int]] | None = None,
    sha256: dict[Path, str] | None = None,
) -> WindowResult:
    """Plays the average of ``window`` (argmax, each robot on its ego-graph) on ``seeds``, or
    reads it back from ``cache``; ``sha256``: the files' hashes when already known."""
    import torch

    from marl_cover import parallel_env
    from marl_cover.agents.evaluation.episodes import evaluate
    from marl_cover.agents.models.policy import GNNPolicy

    steps = [step for step, _ in window]
    files = [str(path) for _, path in window]
    setup = {
        "files": files,
        "sha256": [(sha256 or {}).get(path) or file_sha256(path) for _, path in window],
        "env": env_kwargs,
        "seeds": list(seeds),
    }
    path = cache / f"window_{steps[0]:06d}_{steps[-1]:06d}.json"
    if path.is_file():
        return WindowResult(steps, files, read_result(path, setup)["rewards"])
    torch.set_num_threads(1)
    model, _ = load_window(files)
    hops = max(env_kwargs.get("hops", 0), model.config.hops)  # at least the receptive field
    env = parallel_env(**{**env_kwargs, "hops": hops})
    summary = evaluate(env, GNNPolicy(model), seeds, progress=progress)
    rewards = [result.reward for result in summary.results]
    write_text_atomic(path, json.dumps({"setup": setup, "rewards": rewards}, indent=1))
    return WindowResult(steps, files, rewards)


def select_window(
    folder: str | Path,
    sizes: Iterable[int],
    env_kwargs: dict[str, Any],
    seeds: Sequence[int],
    cache: str | Path,
    progress: Callable[[Iterable[int]], Iterable[int]] | None = None,
) -> tuple[list[WindowResult], WindowResult]:
    """Every trailing window of ``folder``'s snapshots played on ``seeds``, and the best one
    (the highest mean reward; the larger window on a tie).

    Args:
        folder: The run (or its ``steps/`` folder).
        sizes: Window sizes, in snapshots (1: the last snapshot alone).
        env_kwargs: :func:`marl_cover.parallel_env` options (``map``, ``task``, ...); the
            ego-graphs span at least the model's receptive field.
        seeds: Selection episode seeds (paired across windows).
        cache: Folder of the per-window results.
        progress: Optional wrapper such as ``tqdm`` around each window's seed iterator.
    """
    snapshots = snapshot_files(folder)  # before any folder is made
    windows = trailing_windows(snapshots, sizes)
    cache = Path(cache)
    cache.mkdir(parents=True, exist_ok=True)
    hashes = {path: file_sha256(path) for _, path in windows[0]}  # the largest window
    results = [evaluate_window(w, env_kwargs, seeds, cache, progress, hashes) for w in windows]
    best = max(results, key=lambda r: (r.mean, len(r.steps)))
    return results, best
