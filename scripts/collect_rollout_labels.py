"""Record a GNN's own episodes, each state labelled by its one-step rollout policy (DAgger data).

    python scripts/collect_rollout_labels.py [--config FILE] [key=value ...]
    e.g.  python scripts/collect_rollout_labels.py task=exploration episodes=100 seed=30000
          (then, beside it, the same with seed=40000 and another out=)

Each robot's label is the move that returns most when it alone leaves the GNN's move for one
step and every robot follows the GNN to the end of the episode (exact play-outs on copies of the
environment, ``agents.rollout``). ``sequential=true`` labels robot by robot (the rollout
policy's own moves), ``labels=own`` with the GNN's own moves (a control for retraining),
``labels=local`` with the decentralized rollout's moves (``agents.local_rollout``: each robot
plays its moves within ``margin`` of its best logit out on its own ego-graph), and
``beta`` plays the labels instead of the GNN's moves with that probability.

Writes ``OUT/shard_NNNNN.npz`` (``shard_size`` episodes each, atomically, with a ``.json`` of
per-episode counts beside it), ``OUT/config.yaml`` and ``OUT/summary.json``. Running the same
command again finishes the shards that are missing; two commands with different ``seed`` and
``out`` run side by side. Train on them with
``python scripts/train_bc.py ... "dagger.reuse=[OUT,...]"``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.configuration import load_or_exit  # noqa: E402
from agents.rollout_labels import RolloutLabelConfig, collect_rollout_labels  # noqa: E402


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--config", default=None, help="YAML file of RolloutLabelConfig keys")
    parser.add_argument("overrides", nargs="*", help="key=value (dotted for env.*)")
    args = parser.parse_args(argv)
    config = load_or_exit(RolloutLabelConfig, args.config, args.overrides)
    summary = collect_rollout_labels(config)
    print(json.dumps(summary, indent=2))
    return summary


if __name__ == "__main__":
    main()
