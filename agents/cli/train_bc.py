"""Behaviour cloning of the routing expert, with DAgger rounds; resumable.

Trains the aggregation GNN on an expert dataset (``marl-cover collect``); re-running with the
same ``out`` resumes from ``out/checkpoint.pt`` (with more ``dagger.rounds``, a finished run goes
on with the next round). ``init`` starts from a shipped model name or a model file. The recipe
and its outputs: :mod:`marl_cover.agents.training.bc`; prints the run's summary as JSON.

Examples::

    marl-cover train-bc                                        # --config bc_coverage
    marl-cover train-bc model.kind=linear model.hops=7 out=outputs/bc/linear_k7
    marl-cover train-bc init=outputs/bc/nonlinear_k19/best.pt steps=0 dagger.rounds=4 \
        dagger.fraction=0.5 dagger.expert_mode=receding dagger.expert_horizon=19 \
        dagger.expert_clock=false
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from marl_cover.agents.cli.options import parse
from marl_cover.agents.cli.runs import run_training


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover train-bc") -> None:
    """``marl-cover train-bc``: see the module docstring."""
    from marl_cover.agents.training.bc import BCConfig, train_bc

    args = sys.argv[1:] if argv is None else argv
    config = parse(
        BCConfig, args, prog=prog, description=__doc__ or "", preset="bc_coverage", presets=["bc_"]
    )
    run_training(prog, train_bc, config)
