"""Behaviour-cloning sweep over the receptive field: one resumable run per (kind, K).

    python scripts/sweep_bc.py [key=value overrides of train_bc, e.g. steps=3000] \\
        --kinds linear nonlinear --hops 3 5 7 9 11 13 15 17 19 [--out outputs/bc]

(overrides go before ``--kinds``/``--hops``, whose value lists would swallow them).

Each run goes to ``OUT/<kind>_k<K>`` (the folder ``scripts/reproduce_paper.py --models OUT``
reads); a finished run (``model.pt`` present) is skipped, an interrupted one resumes. Every
run's settings are checked before the first one trains.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents import configuration  # noqa: E402
from agents.cli import positive_int  # noqa: E402
from agents.models.gnn import KINDS  # noqa: E402
from agents.training.bc import BCConfig, train_bc  # noqa: E402

DEFAULT_CONFIG = Path(__file__).resolve().parent.parent / "configs" / "bc_coverage.yaml"


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--kinds", nargs="+", default=["linear", "nonlinear"], choices=KINDS)
    parser.add_argument("--hops", nargs="+", type=positive_int, default=list(range(3, 20, 2)))
    parser.add_argument("--config", default=str(DEFAULT_CONFIG))
    parser.add_argument("--out", type=Path, default=Path("outputs/bc"))
    parser.add_argument("overrides", nargs="*")
    args = parser.parse_args(argv)
    runs = [  # every run's config loads (and is checked) before any trains
        configuration.load_or_exit(
            BCConfig,
            args.config,
            [*args.overrides, f"model.kind={kind}", f"model.hops={hops}", f"out={out}"],
        )
        for kind in args.kinds
        for hops in args.hops
        for out in [args.out / f"{kind}_k{hops}"]
    ]
    for config in runs:
        if (Path(config.out) / "model.pt").exists():
            continue
        summary = train_bc(config)
        print(f"{config.model.kind} K={config.model.hops}: {summary}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
