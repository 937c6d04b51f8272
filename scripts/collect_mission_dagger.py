"""Record missions flown by a GNN, each decision labelled by the routing expert (DAgger data).

    python scripts/collect_mission_dagger.py [--config FILE] [key=value ...]
    e.g.  python scripts/collect_mission_dagger.py missions=20 beta=0.3 out=outputs/mission_dagger

Writes ``OUT/shard_NNNNN.npz`` (``shard_size`` missions each, atomically, with a ``.json`` of
per-mission counts beside it), ``OUT/config.yaml`` and ``OUT/summary.json`` (how often the
learner's move was among the expert's). Running the same command again finishes the shards
that are missing. Train on them with ``python scripts/train_bc.py ... "dagger.reuse=[OUT]"``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.configuration import load_or_exit  # noqa: E402
from agents.mission_dagger import MissionDaggerConfig, collect_mission_dagger  # noqa: E402


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default=None, help="YAML file of MissionDaggerConfig keys")
    parser.add_argument("overrides", nargs="*", help="key=value (dotted for dynamics.*)")
    args = parser.parse_args(argv)
    config = load_or_exit(MissionDaggerConfig, args.config, args.overrides)
    summary = collect_mission_dagger(config)
    print(json.dumps(summary, indent=2))
    return summary


if __name__ == "__main__":
    main()
