"""How often a fresh expert plan (or a model) at a recorded state reproduces the dataset's label.

    python scripts/label_agreement.py                      # BC's validation episodes, 5 states each
    python scripts/label_agreement.py --episodes 40 --states 5 --out outputs/label_agreement.json
    python scripts/label_agreement.py --relabel gnn --out outputs/label_agreement_gnn.json
    python scripts/label_agreement.py --plan-steps-left 50 --out outputs/label_agreement_blind.json
    python scripts/label_agreement.py --config configs/bc_exploration.yaml \
        --shards outputs/bc/explore_ties/dagger --episodes 10 --states 50 --relabel gnn \
        --checkpoint agents/models/shipped/exploration_gnn.pt     # DAgger states and labels

The states are those of behaviour cloning's validation split (``configs/bc_coverage.yaml``
unless ``--config``), the labels those recorded in the dataset; each sampled state is relabelled
by a new routing expert with the dataset's settings (``meta.json``: backend, iterations, time
limit) and another solver seed, planning from that state. The agreement bounds how well any
policy of the state can match the labels. ``--relabel gnn`` asks a model instead (argmax of one
pass over ``state()``; ``--checkpoint``, by default the shipped behaviour-cloned model): the
same states, so the two tables compare line by line. ``--plan-steps-left N`` makes the expert
blind to the clock (it plans as if ``N`` actions were left at every state): how much of the
labels a policy without the time could explain. ``--receding H`` relabels with the receding
expert blind to the clock instead (DAgger's labeller, planning ``H`` steps ahead).

``--shards DIR`` takes the episodes from a folder of shards instead (a DAgger run's
``out/dagger``: the learner's states, the expert's labels), replayed in the BC config's ``env``.
Where the episodes record the expert's sets of equally good actions (``Episode.accept``:
every first hop of a shortest path to its goal), the table's last lines give the share of
labels with such ties and how often the relabelled action lies in the set. Prints a table by
step and writes JSON atomically.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.cli import non_negative_int, positive_int, write_text_atomic  # noqa: E402
from agents.configuration import load_or_exit  # noqa: E402
from agents.datasets import load_dataset  # noqa: E402
from agents.label_agreement import label_agreement, with_steps_left  # noqa: E402
from agents.training.bc import BCConfig, split_episodes  # noqa: E402
from marl_cover import parallel_env  # noqa: E402

BC_MODEL = "agents/models/shipped/bc/coverage_gnn.pt"


def expert_relabel(  # noqa: ANN201
    options: dict,
    solver_seed: int,
    plan_steps_left: int | None = None,
    receding: int | None = None,
):
    """A new routing expert with the dataset's settings plans from each state (as if
    ``plan_steps_left`` actions were left, when given; over ``receding`` steps, blind to the
    clock, when given)."""
    from agents.experts import RoutingExpert

    def relabel(env, step: int) -> np.ndarray:  # noqa: ANN001
        expert = RoutingExpert(
            backend=options.get("backend", "pyvrp"),
            mode="open_loop" if receding is None else "receding",
            horizon=receding,
            clock=receding is None,
            time_limit=options.get("time_limit", 0.5),
            max_iterations=options.get("iterations") or None,
            seed=solver_seed + step,
        )
        snapshot = env.snapshot()
        if plan_steps_left is not None:
            snapshot = with_steps_left(snapshot, plan_steps_left)
        return expert.act_snapshot(snapshot)

    return relabel


def gnn_relabel(checkpoint: Path):  # noqa: ANN201
    """The model's argmax actions from one pass over ``state()``."""
    import torch

    from agents.models.policy import GNNPolicy, load_model

    torch.set_num_threads(1)
    try:
        model, _ = load_model(checkpoint)
    except (FileNotFoundError, ValueError) as error:
        raise SystemExit(f"label_agreement: {error}") from error
    policy = GNNPolicy(model, centralized=True)
    return lambda env, step: policy.act_state(env.state())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", type=Path, default=Path("configs/bc_coverage.yaml"))
    parser.add_argument("--episodes", type=positive_int, default=40, help="validation episodes")
    parser.add_argument("--states", type=positive_int, default=5, help="states per episode")
    parser.add_argument("--seed", type=non_negative_int, default=0, help="chooses the states")
    parser.add_argument("--solver-seed", type=non_negative_int, default=12345)
    parser.add_argument("--relabel", choices=("expert", "gnn"), default="expert")
    parser.add_argument(
        "--plan-steps-left",
        type=positive_int,
        default=None,
        help="expert: plan as if this many actions were left (blind to the clock)",
    )
    parser.add_argument(
        "--receding",
        type=positive_int,
        default=None,
        help="expert: the receding expert blind to the clock, planning this many steps",
    )
    parser.add_argument(
        "--shards", type=Path, default=None, help="episodes from this folder of shards"
    )
    parser.add_argument("--checkpoint", type=Path, default=Path(BC_MODEL), help="--relabel gnn")
    parser.add_argument("--out", type=Path, default=Path("outputs/label_agreement.json"))
    args = parser.parse_args()
    config = load_or_exit(BCConfig, args.config, [])
    meta_path = Path(config.dataset) / "meta.json"
    if not meta_path.is_file():
        raise SystemExit(f"label_agreement: no {meta_path} (the dataset's settings)")
    meta = json.loads(meta_path.read_text())
    options = meta["options"]
    if options.get("mode", "open_loop") != "open_loop":
        raise SystemExit(f"label_agreement: {meta_path} is not an open-loop dataset")
    if args.shards is None:
        _, validation = split_episodes(config)
        episodes = validation[: args.episodes]
        env = parallel_env(**meta.get("env", {}))
    else:
        try:
            episodes = load_dataset(args.shards)[: args.episodes]
        except (FileNotFoundError, ValueError) as error:
            raise SystemExit(f"label_agreement: {error}") from error
        env = parallel_env(**config.env)

    relabel = expert_relabel(options, args.solver_seed, args.plan_steps_left, args.receding)
    if args.relabel == "gnn":
        relabel = gnn_relabel(args.checkpoint)

    start = time.perf_counter()

    def progress(done: int) -> None:
        if sys.stderr.isatty() or done % 10 == 0 or done == len(episodes):
            end = "" if sys.stderr.isatty() else "\n"
            print(f"\r{done}/{len(episodes)} episodes", end=end, file=sys.stderr, flush=True)

    result = label_agreement(
        env, episodes, relabel, args.states, np.random.default_rng(args.seed), progress=progress
    )
    if sys.stderr.isatty():
        print(file=sys.stderr)
    print(f"{'steps':>8s} {'agreed':>7s} {'of':>5s} {'fraction':>9s}")
    for first, (agreed, total) in result.by_step.items():
        print(f"{first:3d}..{first + 9:<3d} {agreed:7d} {total:5d} {agreed / total:9.3f}")
    print(f"{'all':>8s} {result.agreed:7d} {result.total:5d} {result.fraction:9.3f}")
    print(f"{'in set':>8s} {result.in_set:7d} {result.total:5d} {result.set_fraction:9.3f}")
    print(f"{'tied':>8s} {result.tied:7d} {result.total:5d} {result.tied_fraction:9.3f}")
    record = {
        "dataset": config.dataset if args.shards is None else str(args.shards),
        "episodes": [e.seed for e in episodes],
        "states_per_episode": args.states,
        "seed": args.seed,
        "relabel": args.relabel,
        "solver_seed": args.solver_seed if args.relabel == "expert" else None,
        "plan_steps_left": args.plan_steps_left if args.relabel == "expert" else None,
        "receding": args.receding if args.relabel == "expert" else None,
        "checkpoint": str(args.checkpoint) if args.relabel == "gnn" else None,
        "expert": {k: options.get(k) for k in ("backend", "time_limit", "iterations")},
        "agreement": result.fraction,
        "agreed": result.agreed,
        "total": result.total,
        "by_step": result.by_step,
        "in_set": result.in_set,
        "set_agreement": result.set_fraction,
        "tied": result.tied,
        "seconds": round(time.perf_counter() - start, 1),
    }
    write_text_atomic(args.out, json.dumps(record, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
