"""Behaviour cloning of the routing expert (TorchRL storage and loggers); resumable.

    python scripts/train_bc.py                                    # configs/bc_coverage.yaml
    python scripts/train_bc.py model.kind=linear model.hops=7 out=outputs/bc/linear_k7
    python scripts/train_bc.py --config configs/bc_coverage.yaml steps=300 max_episodes=20
    python scripts/train_bc.py dagger.rounds=2 dagger.episodes=50

Re-running with the same ``out`` resumes from ``out/checkpoint.pt``. Any key of
``agents.training.bc.BCConfig`` (``section.key`` for ``model.*`` and ``dagger.*``) can be
overridden; an unknown key is an error.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents import configuration  # noqa: E402
from agents.training.bc import BCConfig, train_bc  # noqa: E402

DEFAULT_CONFIG = Path(__file__).resolve().parent.parent / "configs" / "bc_coverage.yaml"


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--config", default=str(DEFAULT_CONFIG), help="YAML preset")
    parser.add_argument("overrides", nargs="*", help="key=value overrides")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    import torchrl  # noqa: F401 (configures its logger on import; quieten it after)

    logging.getLogger("torchrl").setLevel(logging.WARNING)  # it logs buffer set-up to stdout
    try:
        config = configuration.load(BCConfig, args.config, args.overrides)
    except (ValueError, FileNotFoundError) as error:
        raise SystemExit(str(error)) from error
    summary = train_bc(config)
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main(sys.argv[1:])
