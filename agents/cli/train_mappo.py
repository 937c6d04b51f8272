"""MAPPO / IPPO with TorchRL on the batched environment; resumable.

Re-running with the same ``out`` resumes from ``out/checkpoint.pt``; ``collector.n_iters`` may
grow between runs. ``init`` starts the actor from a shipped model name or a model file (a
fine-tune). The loop and its outputs: :mod:`marl_cover.agents.training.mappo`; prints the run's
summary as JSON.

Examples::

    marl-cover train-mappo                                     # --config mappo_coverage
    marl-cover train-mappo collector.n_iters=2 collector.frames_per_batch=200
    marl-cover train-mappo algorithm=ippo out=outputs/mappo/ippo
    marl-cover train-mappo --config mappo_finetune init=outputs/bc/nonlinear_k19/best.pt
    marl-cover train-mappo device=cuda collector.workers=4
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from marl_cover.agents.cli.options import parse
from marl_cover.agents.cli.runs import run_training


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover train-mappo") -> None:
    """``marl-cover train-mappo``: see the module docstring."""
    from marl_cover.agents.training.mappo import MAPPOConfig, train_mappo

    args = sys.argv[1:] if argv is None else argv
    config = parse(
        MAPPOConfig,
        args,
        prog=prog,
        description=__doc__ or "",
        preset="mappo_coverage",
        presets=["mappo_"],
    )
    run_training(prog, train_mappo, config)
