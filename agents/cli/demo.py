"""The shipped GNN beside greedy and the routing expert on fresh procedural cities.

Prints a comparison table (paired episodes: mean reward +- SEM, the share of points of interest
covered, the controller's milliseconds per step) and writes an animation of one GNN episode.
In exploration the map is discovered with a 22 m sensor (undiscovered parts are faded in the
animation) and the expert runs twice: omniscient (plans on the true map, the imitation teacher)
and fair (plans only on what the team has discovered). The GNN was trained on windows of the
paper's map: procedural cities are maps it never saw. Without the ``train`` extra (torch) or the
``expert`` extra (PyVRP) those rows are skipped.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from marl_cover import parallel_env
from marl_cover.agents.baselines.greedy import GreedyPolicy
from marl_cover.agents.cli.options import parse
from marl_cover.agents.evaluation.episodes import evaluate
from marl_cover.config import TASKS, require


@dataclass
class DemoConfig:
    """What the demo plays."""

    task: str = "coverage"  # coverage or exploration
    episodes: int = 10  # fresh cities, one episode each
    robots: int = 4  # team size
    city_size: int = 228  # waypoints of each city
    expert_iterations: int = 800  # PyVRP iterations per plan (the same table on every machine)
    seed: int = 1000  # first city seed
    out: str = "outputs/demo"  # folder of the GIF

    def __post_init__(self) -> None:
        require(
            (self.task in TASKS, f"task must be one of {TASKS}, got {self.task!r}"),
            (min(self.episodes, self.robots, self.city_size) >= 1, "counts must be >= 1"),
            (self.expert_iterations >= 1, "expert_iterations must be >= 1"),
            (self.seed >= 0, f"seed must be >= 0, got {self.seed}"),
        )


def load_gnn(task: str) -> Any:
    """The shipped default model of ``task``, or ``None`` without torch."""
    try:
        import torch
    except ImportError:
        print("torch is not installed (the train extra): no GNN row")
        return None
    from marl_cover.agents.models.checkpoints import load_model
    from marl_cover.agents.models.shipped import default_model, model_path

    torch.set_num_threads(1)
    model, _ = load_model(model_path(default_model(task)))
    return model


def make_policies(model: Any, hops: int, expert_iterations: int, task: str) -> dict[str, Any]:
    """The table's rows: the GNN (when torch is there), greedy, the expert(s)."""
    policies: dict[str, Any] = {}
    if model is not None:
        from marl_cover.agents.models.policy import GNNPolicy

        policies[f"GNN {model.config.kind}, K={model.config.hops} (shipped)"] = GNNPolicy(model)
    policies[f"greedy, K={hops}"] = GreedyPolicy(hops, fallback="random")
    try:
        from marl_cover.agents.experts import RoutingExpert

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


def run(config: DemoConfig) -> None:
    """Prints the table and writes the GIF."""
    model = load_gnn(config.task)
    hops = model.config.hops if model is not None else 19
    env_kwargs: dict[str, Any] = {
        "task": config.task,
        "num_robots": config.robots,
        "hops": hops,
        "city_size": config.city_size,
    }
    env = parallel_env(**env_kwargs)
    seeds = range(config.seed, config.seed + config.episodes)
    print(
        f"{config.task}: {config.robots} robots, K = {hops}, T = {env.config.max_steps}, "
        f"{config.episodes} fresh procedural cities of {config.city_size} waypoints "
        f"(seeds {seeds.start}..{seeds.stop - 1})"
    )
    print(f"{'policy':<48} {'reward':>15} {'coverage':>9} {'policy ms/step':>15}")
    for name, policy in make_policies(model, hops, config.expert_iterations, config.task).items():
        s = evaluate(env, policy, seeds)
        print(
            f"{name:<48} {s.mean:7.1f} +- {s.sem:4.1f} {100 * s.mean_coverage:8.1f}% "
            f"{s.controller_ms_per_step:15.2f}"
        )
    if model is not None:
        from marl_cover.agents.models.policy import GNNPolicy

        name = "gnn_city.gif" if config.task == "coverage" else "gnn_city_explore.gif"
        path = Path(config.out) / name
        animate(env_kwargs, GNNPolicy(model), seeds.start, path)
        print(f"wrote {path}")


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover demo") -> None:
    """``marl-cover demo``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    run(parse(DemoConfig, args, prog=prog, description=__doc__ or ""))
