"""Behaviour cloning of the routing expert (TorchRL storage and loggers); resumable.

    python scripts/train_bc.py                                    # configs/bc_coverage.yaml
    python scripts/train_bc.py model.kind=linear model.hops=7 out=outputs/bc/linear_k7
    python scripts/train_bc.py --config configs/bc_coverage.yaml steps=300 max_episodes=20
    python scripts/train_bc.py dagger.rounds=2 dagger.episodes=50
    python scripts/train_bc.py init=MODEL.pt steps=0 dagger.rounds=4 dagger.fraction=0.5 \
        dagger.expert_mode=receding dagger.expert_horizon=19 dagger.expert_clock=false
    python scripts/train_bc.py init=MODEL.pt steps=0 dagger.rounds=2 dagger.fraction=0.25 \
        dagger.expert_mode=receding dagger.expert_horizon=19 dagger.expert_clock=false \
        dagger.env.map=paper_full dagger.env.num_robots=10 dagger.env.max_steps=131 \
        select_env.map=paper_full select_env.num_robots=10 select_env.max_steps=131 select_seed=100
    python scripts/train_bc.py init=MODEL.pt steps=0 dagger.rounds=4 dagger.fraction=0.5 \
        dagger.expert_mode=receding dagger.expert_horizon=19 dagger.expert_clock=false \
        ties=true     # learn the expert's set of equally short moves, not its tie-break
    python scripts/train_bc.py --config configs/bc_exploration.yaml init=MODEL.pt steps=0 \
        dagger.rounds=5 dagger.fraction=0.5 dagger.expert_mode=receding \
        dagger.expert_horizon=19 dagger.expert_clock=false \
        dagger.expert_information=expected   # exploration labels from the floor plan

Re-running with the same ``out`` resumes from ``out/checkpoint.pt`` (with more
``dagger.rounds``, a finished run goes on with the next round). Any key of
``agents.training.bc.BCConfig`` (``section.key`` for ``model.*`` and ``dagger.*``) can be
overridden; an unknown key is an error. ``--print-config`` prints the settings a run
would use (the preset with the overrides) as YAML for ``--config``, and trains nothing.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.training.bc import BCConfig, train_bc  # noqa: E402
from agents.training.runs import command_line  # noqa: E402

DEFAULT_CONFIG = Path(__file__).resolve().parent.parent / "configs" / "bc_coverage.yaml"


def main(argv: list[str]) -> None:
    command_line(argv, __doc__, BCConfig, DEFAULT_CONFIG, train_bc)


if __name__ == "__main__":
    main(sys.argv[1:])
