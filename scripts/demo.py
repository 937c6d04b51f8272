"""Demo: the shipped GNN beside greedy and the routing expert on fresh procedural cities.

Prints a comparison table (paired episodes) and writes an animation of one GNN episode.

    python scripts/demo.py [--task coverage|exploration] [--episodes 10] [--robots 4]
                           [--city-size 228] [--out outputs/demo]

In exploration the map is discovered with a 22 m sensor (undiscovered parts are faded in the
animation); the expert runs twice: omniscient (plans on the true map, the imitation teacher)
and fair (plans only on what the team has discovered).

The GNN was trained on windows of the paper's map; procedural cities are maps it never saw.
Without the ``train`` extra (torch) or the ``expert`` extra (PyVRP) those rows are skipped.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.cli import non_negative_int, positive_int  # noqa: E402
from agents.evaluation import evaluate  # noqa: E402
from agents.greedy import GreedyPolicy  # noqa: E402
from marl_cover import parallel_env  # noqa: E402


def load_gnn(task: str) -> Any:
    """The shipped model of ``task``, or ``None`` without torch."""
    try:
        import torch
    except ImportError:
        print("torch is not installed (the train extra): no GNN row")
        return None
    from agents.models.policy import load_model
    from agents.models.shipped import shipped_model_path

    torch.set_num_threads(1)
    model, _ = load_model(shipped_model_path(task))
    return model


def make_policies(model: Any, hops: int, expert_iterations: int, task: str) -> dict[str, Any]:
    policies: dict[str, Any] = {}
    if model is not None:
        from agents.models.policy import GNNPolicy

        policies[f"GNN {model.config.kind}, K={model.config.hops} (shipped)"] = GNNPolicy(model)
    policies[f"greedy, K={hops}"] = GreedyPolicy(hops, fallback="random")
    try:
        from agents.experts import RoutingExpert

        # iteration-limited solves: the same table on every machine
        kinds = {"full": ""} if task == "coverage" else {"full": "omniscient, ", "known": "fair, "}
        for information, label in kinds.items():
            name = f"expert ({label}PyVRP open loop, {expert_iterations} it.)"
            policies[name] = RoutingExpert(
                max_iterations=expert_iterations, information=information
            )
    except ImportError:
        print("PyVRP is not installed (the expert extra): no expert row")
    return policies


def animate(env_kwargs: dict[str, Any], policy: Any, seed: int, path: Path) -> None:
    """Plays one episode and writes its frames as a GIF."""
    import matplotlib

    matplotlib.use("Agg")
    from PIL import Image

    env = parallel_env(**env_kwargs, render_mode="rgb_array")
    observations, _ = env.reset(seed=seed)
    frames = [env.render()]
    while env.agents:
        observations, *_ = env.step(policy.act(observations))
        frames.append(env.render())
    env.close()
    images = [
        Image.fromarray(np.asarray(frame)).convert("P", palette=Image.Palette.ADAPTIVE)
        for frame in frames  # (H, W, 3) uint8 images in rgb_array mode
    ]
    path.parent.mkdir(parents=True, exist_ok=True)
    images[0].save(
        path, save_all=True, append_images=images[1:] + [images[-1]] * 10, duration=150, loop=0
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", choices=["coverage", "exploration"], default="coverage")
    parser.add_argument("--episodes", type=positive_int, default=10)
    parser.add_argument("--robots", type=positive_int, default=4)
    parser.add_argument("--city-size", type=positive_int, default=228)
    parser.add_argument(
        "--expert-iterations", type=int, default=800, help="PyVRP iterations per plan"
    )
    parser.add_argument("--seed", type=non_negative_int, default=1000, help="first city seed")
    parser.add_argument("--out", type=Path, default=Path("outputs/demo"))
    args = parser.parse_args()
    model = load_gnn(args.task)
    hops = model.config.hops if model is not None else 19
    env_kwargs = {
        "task": args.task,
        "num_robots": args.robots,
        "hops": hops,
        "city_size": args.city_size,
    }
    env = parallel_env(**env_kwargs)
    seeds = range(args.seed, args.seed + args.episodes)
    print(
        f"{args.task}: {args.robots} robots, K = {hops}, T = {env.config.max_steps}, "
        f"{args.episodes} fresh procedural cities of {args.city_size} waypoints "
        f"(seeds {seeds.start}..{seeds.stop - 1})"
    )
    print(f"{'policy':<48} {'reward':>15} {'coverage':>9} {'policy ms/step':>15}")
    for name, policy in make_policies(model, hops, args.expert_iterations, args.task).items():
        s = evaluate(env, policy, seeds)
        print(
            f"{name:<48} {s.mean:7.1f} +- {s.sem:4.1f} {100 * s.mean_coverage:8.1f}% "
            f"{s.controller_ms_per_step:15.2f}"
        )
    if model is not None:
        from agents.models.policy import GNNPolicy

        path = args.out / ("gnn_city.gif" if args.task == "coverage" else "gnn_city_explore.gif")
        animate(env_kwargs, GNNPolicy(model), seeds.start, path)
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
