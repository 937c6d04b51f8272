"""The weight average of a run's last snapshots, its window chosen on selection seeds.

``run`` is a behaviour-cloning or MAPPO run trained with ``snapshots=true`` (its ``steps/``
folder). For each size ``n`` of ``sizes``, the mean of the last ``n`` snapshots plays one episode
per selection seed (``seed`` .. ``seed + episodes - 1``, never the test seeds 0..99); the table
gives each window's mean reward and its paired difference with the best, which is written to
``out/average.pt`` (a model file for ``marl-cover evaluate model=...``) beside
``out/selection.json``. Per-window results are kept in ``out/windows/``: an interrupted call
resumes, and a second call with more sizes plays only the new windows. With ``files`` instead,
the mean of those model files (one config) is written to ``out`` without any selection.

Examples::

    marl-cover average run=outputs/bc/cov_perhop sizes=[5,7,9]
    marl-cover average files=[a/model.pt,b/model.pt] out=outputs/soup.pt
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

from marl_cover import EnvSettings
from marl_cover.agents.cli.options import parse
from marl_cover.agents.io import progress_bar, write_text_atomic
from marl_cover.config import require


@dataclass
class AverageConfig:
    """What to average, and on which seeds to choose."""

    run: str | None = None  # a run folder with steps/step_NNNNNN.pt
    files: list[str] = field(default_factory=list)  # or: model files averaged as they are
    sizes: list[int] = field(default_factory=lambda: [1, 3, 5, 7, 9])  # window sizes
    episodes: int = 100  # selection episodes
    seed: int = 10_000  # first selection seed
    out: str | None = None  # default: RUN/average (with files: required, the .pt to write)
    env: EnvSettings = field(default_factory=lambda: EnvSettings(map="paper"))

    def __post_init__(self) -> None:
        require(
            (all(size >= 1 for size in self.sizes), f"sizes must be >= 1, got {self.sizes}"),
            (self.episodes >= 1 and self.seed >= 0, "episodes must be >= 1 and seed >= 0"),
        )


def average_files(config: AverageConfig) -> None:
    """Writes the mean of ``files`` to ``out``."""
    from marl_cover.agents.models.checkpoints import average_models, save_model

    if config.out is None:
        raise SystemExit("marl-cover average: files= needs out= (the model file to write)")
    try:
        model, metadata = average_models(config.files)
    except (FileNotFoundError, ValueError) as error:
        raise SystemExit(f"marl-cover average: {error}") from None
    save_model(config.out, model, metadata)
    print(f"wrote {config.out}: the mean of {len(config.files)} {model.config.kind} models")


def select(config: AverageConfig) -> None:
    """Plays every window, prints the table, writes the best window's average."""
    from marl_cover.agents.models.checkpoints import save_model
    from marl_cover.agents.training.averaging import load_window, select_window

    assert config.run is not None
    run = Path(config.run)
    out = Path(config.out) if config.out else run / "average"
    env_kwargs = config.env.as_kwargs()
    seeds = list(range(config.seed, config.seed + config.episodes))
    progress = progress_bar("episodes", leave=False)
    try:
        results, best = select_window(
            run, config.sizes, env_kwargs, seeds, out / "windows", progress
        )
    except (FileNotFoundError, ValueError) as error:
        raise SystemExit(f"marl-cover average: {error}") from None
    print(f"{config.env.task} on {config.env.map}, seeds {seeds[0]}..{seeds[-1]}")
    print(f"{'window':<28} {'mean':>7} {'SEM':>6} {'vs best':>16}")
    for result in results:
        diff, sem = result.paired(best)
        mark = "  <- best" if result is best else ""
        print(
            f"{result.name:<28} {result.mean:7.2f} {result.sem:6.2f} "
            f"{diff:+8.2f} +- {sem:4.2f}{mark}"
        )
    model, metadata = load_window(best.files)
    selection = {
        "seeds": f"{seeds[0]}..{seeds[-1]}",
        "config": asdict(config),
        "chosen": best.name,
        "windows": {r.name: {"mean": round(r.mean, 3), "sem": round(r.sem, 3)} for r in results},
    }
    save_model(out / "average.pt", model, {**metadata, "selection": selection})
    write_text_atomic(out / "selection.json", json.dumps(selection, indent=1))
    print(f"wrote {out / 'average.pt'} ({best.name}) and {out / 'selection.json'}")


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover average") -> None:
    """``marl-cover average``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    config = parse(AverageConfig, args, prog=prog, description=__doc__ or "")
    if bool(config.files) == (config.run is not None):
        raise SystemExit(f"{prog}: give either run= (a run folder) or files= (model files)")
    average_files(config) if config.files else select(config)
