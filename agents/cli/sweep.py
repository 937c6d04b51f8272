"""Behaviour-cloning sweep over the receptive field: one resumable run per (kind, K).

Each run goes to ``out/<kind>_k<K>`` (the folder ``marl-cover reproduce-paper models=OUT``
reads) with the settings of ``--config`` (a ``train-bc`` preset) and the ``bc.*`` overrides; a
finished run (``model.pt`` present) is skipped, an interrupted one resumes. Every run's
settings are checked before the first one trains.

Example::

    marl-cover sweep kinds=[linear,nonlinear] hops=[3,5,7,9,11,13,15,17,19] bc.steps=3000
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from marl_cover.agents.cli.options import load, parse
from marl_cover.agents.cli.runs import run_training
from marl_cover.agents.training.bc import BCConfig, train_bc
from marl_cover.config import require


def _default_bc() -> BCConfig:
    return load(BCConfig, "bc_coverage")


@dataclass
class SweepConfig:
    """The grid of runs."""

    kinds: list[str] = field(default_factory=lambda: ["linear", "nonlinear"])  # model kinds
    hops: list[int] = field(default_factory=lambda: list(range(3, 20, 2)))  # receptive fields
    out: str = "outputs/bc"  # each run in out/<kind>_k<K>
    bc: BCConfig = field(default_factory=_default_bc)  # the train-bc settings of every run

    def __post_init__(self) -> None:
        require(
            (all(k in ("linear", "nonlinear") for k in self.kinds), f"kinds: {self.kinds}"),
            (all(h >= 1 for h in self.hops), f"hops must be >= 1, got {self.hops}"),
        )


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover sweep") -> None:
    """``marl-cover sweep``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    config = parse(SweepConfig, args, prog=prog, description=__doc__ or "")
    runs = [
        replace(
            config.bc,
            model=replace(config.bc.model, kind=kind, hops=hops),
            out=str(Path(config.out) / f"{kind}_k{hops}"),
        )
        for kind in config.kinds
        for hops in config.hops
    ]
    for run in runs:
        if (Path(run.out) / "model.pt").exists():
            continue
        print(f"{run.model.kind} K={run.model.hops} -> {run.out}", flush=True)
        run_training(prog, train_bc, run)
