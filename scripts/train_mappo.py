"""MAPPO / IPPO with TorchRL on the batched coverage environment; resumable.

    python scripts/train_mappo.py                                 # configs/mappo_coverage.yaml
    python scripts/train_mappo.py collector.n_iters=2 collector.frames_per_batch=200
    python scripts/train_mappo.py algorithm=ippo out=outputs/mappo/ippo
    python scripts/train_mappo.py init=agents/models/shipped/bc/coverage_gnn.pt \\
        optim.critic_warmup_iters=10 out=outputs/mappo/finetune          # fine-tune a BC model
    python scripts/train_mappo.py device=cuda collector.workers=4

Any key of ``agents.training.mappo.MAPPOConfig`` can be overridden (``section.key=value`` for
``collector``, ``loss``, ``optim``, ``model``, ``eval``; ``env.key=value`` for the environment's
``CoverageConfig`` fields); an unknown key is an error. Re-running with the same ``out`` resumes
from ``out/checkpoint.pt``; ``collector.n_iters`` may grow between runs. ``--print-config``
prints the settings a run would use (the preset with the overrides) as YAML for ``--config``,
and trains nothing.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.training.mappo import MAPPOConfig, train_mappo  # noqa: E402
from agents.training.runs import command_line  # noqa: E402

DEFAULT_CONFIG = Path(__file__).resolve().parent.parent / "configs" / "mappo_coverage.yaml"


def main(argv: list[str]) -> None:
    command_line(argv, __doc__, MAPPOConfig, DEFAULT_CONFIG, train_mappo)


if __name__ == "__main__":
    main(sys.argv[1:])
