"""Averages the weights of GNN model files that share one config (a "model soup").

    python scripts/average_models.py OUT.pt RUN_A/model.pt RUN_B/model.pt [...]
    e.g.  python scripts/average_models.py outputs/mappo/soup/model.pt \\
        outputs/mappo/finetune_t05_own/model.pt outputs/mappo/ft_own_s1/model.pt \\
        outputs/mappo/ft_own_s2/model.pt

The result is a model file like any other (``scripts/evaluate.py checkpoint=OUT.pt``); its
metadata is the first file's, with ``average_of`` naming every file.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.models.policy import average_models, save_model  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="the averaged model file to write")
    parser.add_argument("models", type=Path, nargs="+", help="model files with one config")
    args = parser.parse_args()
    model, metadata = average_models(args.models)
    save_model(args.out, model, metadata)
    config = model.config
    print(f"wrote {args.out}: the mean of {len(args.models)} {config.kind} K={config.hops} models")


if __name__ == "__main__":
    main()
