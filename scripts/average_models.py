"""Averages the weights of GNN model files that share one config (a "model soup"), or with
``--logits`` their logits (an ensemble merged into one wider network).

    python scripts/average_models.py OUT.pt RUN_A/model.pt RUN_B/model.pt [...]
    python scripts/average_models.py --logits OUT.pt RUN_A/model.pt RUN_B/model.pt [...]
    e.g.  python scripts/average_models.py outputs/mappo/soup/model.pt \\
        outputs/mappo/finetune_t05_own/model.pt outputs/mappo/ft_own_s1/model.pt \\
        outputs/mappo/ft_own_s2/model.pt

The result is a model file like any other (``scripts/evaluate.py checkpoint=OUT.pt``); its
metadata is the first file's, with ``average_of`` naming every file. With ``--logits`` the
members sit side by side in a network as many times as wide (``AggregationGNN.merged``): it
takes the actions of ``EnsemblePolicy`` on the same files in one forward pass, and its metadata
is ``{"merged_of": [the files]}``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.models.policy import average_models, merge_models, save_model  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="the averaged model file to write")
    parser.add_argument("models", type=Path, nargs="+", help="model files with one config")
    parser.add_argument(
        "--logits", action="store_true", help="average the logits (merge), not the weights"
    )
    args = parser.parse_args()
    merge = merge_models if args.logits else average_models
    try:
        model, metadata = merge(args.models)
    except (FileNotFoundError, ValueError) as error:
        raise SystemExit(f"average_models: {error}") from error
    what = f"the {'members' if args.logits else 'mean'} of {len(args.models)}"
    save_model(args.out, model, metadata)
    config = model.config
    print(f"wrote {args.out}: {what} {config.kind} K={config.hops} models (width {config.hidden})")


if __name__ == "__main__":
    main()
