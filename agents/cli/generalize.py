"""GNN beside greedy as the team grows: 10 to 100 robots on the paper's 5659-waypoint map (the
paper's Fig. "generalize"), or 10 to 1000 and more on procedural cities sized in proportion.

The GNN was trained with 4 robots on ~228-waypoint windows; here it runs (T = 50, K = the
model's receptive field) in one centralized pass per step over the team's graph (the same
actions as each robot on its own ego-graph, tested). Greedy (random moves when nothing is in
reach, as in the paper) runs on each robot's ego-graph on the paper's map, and in one pass over
the team's graph on cities (the same actions, tested). Seeds are paired across methods.

``map=paper_large`` (the default): the paper's map, the table beside the paper's numbers.
``map=city``: each episode a new procedural city of ``waypoints_per_robot`` waypoints a robot
(56.59, the paper's map with 100 robots), compact observations; the table gives the reward per
robot and the paired ratio, also written to ``out/generalize.csv``. ``methods=[...]`` may add
``assign``, the omniscient assignment planner (robots matched to distinct points of interest
each step, with the whole map), and upper bounds on any policy, per seed: ``reach`` (the
points of interest within 50 hops of a robot's start) and ``route`` (also counting the moves
each robot has: :mod:`marl_cover.agents.evaluation.bounds`).

Each (method, team size) result is written to ``out/<method>_R<robots>.json`` when done, with
its setup (task, map, seeds, the model's SHA-256), and read back when present (resumable); a
file made under another setup is an error. Draws ``out/generalize.png``.

Example::

    marl-cover generalize robots=[10,100] episodes=20
    marl-cover generalize map=city robots=[10,100,1000] episodes=10 out=outputs/generalize_city
    marl-cover generalize map=city robots=[1000] episodes=10 methods=[assign,route] \
        out=outputs/generalize_city
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from marl_cover import parallel_env
from marl_cover.agents.baselines.assignment import AssignmentPolicy
from marl_cover.agents.baselines.greedy import CentralizedGreedyPolicy, GreedyPolicy
from marl_cover.agents.cli.options import parse
from marl_cover.agents.evaluation.bounds import episode_bound
from marl_cover.agents.evaluation.episodes import evaluate
from marl_cover.agents.evaluation.paper import paper_numbers
from marl_cover.agents.evaluation.plots import plot_beside_paper
from marl_cover.agents.io import file_sha256, read_json, read_result, write_text_atomic
from marl_cover.config import TASKS, require

PAPER_METHODS = {"greedy": "greedy", "gnn": "gnn_nonlinear_bc"}
#: ``assign``: the omniscient assignment planner (:class:`AssignmentPolicy`), a centralized
#: reference with the whole map.
#: Not policies but upper bounds on any policy's reward, per seed (:mod:`..evaluation.bounds`).
BOUNDS = ("reach", "route")
METHODS = (*PAPER_METHODS, "assign", *BOUNDS)
MAPS = ("paper_large", "city")


@dataclass
class GeneralizeConfig:
    """Team sizes, seeds and the model."""

    task: str = "coverage"  # coverage or exploration
    robots: list[int] = field(default_factory=lambda: [10, 20, 30, 40, 50, 100])  # team sizes
    episodes: int = 100  # episodes per team size
    seed: int = 0  # first seed
    model: str | None = None  # a shipped name or a model file (None: the task's default)
    methods: list[str] = field(
        default_factory=lambda: ["greedy", "gnn"]
    )  # greedy, gnn, assign, reach, route
    map: str = "paper_large"  # paper_large (the paper's map) or city (sized by the team)
    waypoints_per_robot: float = 56.59  # map=city: city size a robot
    out: str = "outputs/generalize"  # results, table and plot
    table_only: bool = False  # print the table of the results on disk, run nothing

    def __post_init__(self) -> None:
        require(
            (self.task in TASKS, f"task must be one of {TASKS}, got {self.task!r}"),
            (all(r >= 1 for r in self.robots), f"robots must be >= 1, got {self.robots}"),
            (self.episodes >= 1 and self.seed >= 0, "episodes must be >= 1 and seed >= 0"),
            (set(self.methods) <= set(METHODS), f"methods: {METHODS}; got {self.methods}"),
            (self.map in MAPS, f"map must be one of {MAPS}, got {self.map!r}"),
            (
                self.waypoints_per_robot >= 1,
                f"waypoints_per_robot must be >= 1, got {self.waypoints_per_robot}",
            ),
        )

    def env_kwargs(self, robots: int, hops: int) -> dict[str, Any]:
        """The environment of a team size."""
        common = {"num_robots": robots, "hops": hops, "max_steps": 50, "task": self.task}
        if self.map == "paper_large":
            return {**common, "map": "paper_large"}
        size = round(self.waypoints_per_robot * robots)
        return {**common, "map": "city", "city_size": size, "observation_mode": "compact"}


def setup(method: str, robots: int, config: GeneralizeConfig, sha256: str) -> dict[str, Any]:
    """What decides one (method, team size) result: a file made under another is not reused."""
    return {
        "method": method,
        "task": config.task,
        "robots": robots,
        "episodes": config.episodes,
        "seed": config.seed,
        "model_sha256": sha256 if method == "gnn" else None,
        **(
            {}
            if config.map == "paper_large"
            else {"map": "city", "waypoints_per_robot": config.waypoints_per_robot}
        ),
    }


def play(method: str, robots: int, config: GeneralizeConfig, model: Any, sha: str) -> dict:
    """One (method, team size) result over the seeds."""
    hops = model.config.hops
    env = parallel_env(**config.env_kwargs(robots, hops))
    seeds = range(config.seed, config.seed + config.episodes)
    head = {
        "method": method,
        "task": config.task,
        "robots": robots,
        "waypoints": env.max_waypoints,
        "hops": hops,
        "episodes": config.episodes,
        "seed": config.seed,
        "model": config.model if method == "gnn" else None,
    }
    if method in BOUNDS:
        bounds = np.array([episode_bound(env, seed, method) for seed in seeds], dtype=np.float64)
        sem = float(bounds.std(ddof=1) / np.sqrt(len(bounds))) if len(bounds) > 1 else 0.0
        return {
            **head,
            "mean": float(bounds.mean()),
            "std": float(bounds.std(ddof=1)) if len(bounds) > 1 else 0.0,
            "sem": sem,
            "rewards": bounds.tolist(),
            "controller_ms_per_step": None,
            "setup": setup(method, robots, config, sha),
        }
    policy: Any
    if method == "gnn":
        from marl_cover.agents.models.policy import GNNPolicy

        policy = GNNPolicy(model, centralized=True)
    elif method == "assign":
        policy = AssignmentPolicy()
    elif config.map == "paper_large":
        policy = GreedyPolicy(hops, fallback="random")
    else:
        policy = CentralizedGreedyPolicy(hops, fallback="random")
    summary = evaluate(env, policy, seeds)
    return {
        **head,
        "mean": summary.mean,
        "std": summary.std,
        "sem": summary.sem,
        "rewards": [r.reward for r in summary.results],
        "controller_ms_per_step": summary.controller_ms_per_step,
        "setup": setup(method, robots, config, sha),
    }


def table(records: dict, paper: dict) -> None:
    """Ours beside the paper's, per team size, with the ratio of the means."""
    print(
        f"{'R':>4} {'greedy ours':>16} {'GNN ours':>16} {'ratio (paired)':>18} "
        f"{'greedy paper':>16} {'GNN paper':>16}"
    )
    for robots in sorted({k[1] for k in records}):
        greedy, gnn = records.get(("greedy", robots)), records.get(("gnn", robots))
        cells = [f"{r['mean']:7.1f} +- {r['sem']:4.1f}" if r else "-" for r in (greedy, gnn)]
        ratio = "-"
        if greedy and gnn and len(greedy["rewards"]) == len(gnn["rewards"]):
            ratios = np.array(gnn["rewards"]) / np.maximum(np.array(greedy["rewards"]), 1)
            ratio = f"{gnn['mean'] / greedy['mean']:5.3f} ({np.median(ratios):.3f} med)"
        for name in ("greedy", "gnn"):
            value = paper.get((PAPER_METHODS[name], robots))
            cells.append(f"{value[0]:7.1f} +- {value[1]:4.1f}" if value else "-")
        print(
            f"{robots:>4} {cells[0]:>16} {cells[1]:>16} {ratio:>18} {cells[2]:>16} {cells[3]:>16}"
        )


def plot(records: dict, paper: dict, path: Path, task: str) -> None:
    """Mean +- SEM against team size, ours (solid) and the paper's (dashed)."""
    curves = {
        method: (
            [(k[1], r["mean"], r["sem"]) for k, r in records.items() if k[0] == method],
            [(k[1], *v) for k, v in paper.items() if k[0] == PAPER_METHODS[method]],
        )
        for method in ("greedy", "gnn")
    }
    plot_beside_paper(
        curves,
        path,
        "robots",
        "points of interest visited in 50 steps (mean +- SEM)",
        f"{task.capitalize()} on the 5659-waypoint map, K = 19",
    )


def scale_rows(records: dict) -> list[dict[str, Any]]:
    """One row per team size with both methods: rewards, reward per robot, and the ratio of
    the means with the mean +- SEM of the paired per-seed ratios; where they were played, the
    assignment planner (its paired ratio to greedy) and the bounds (the GNN's share of the
    tightest, ``route`` over ``reach``)."""
    rows = []
    for robots in sorted({k[1] for k in records}):
        greedy, gnn = records.get(("greedy", robots)), records.get(("gnn", robots))
        if not (greedy and gnn) or len(greedy["rewards"]) != len(gnn["rewards"]):
            continue
        paired = np.array(gnn["rewards"]) / np.maximum(np.array(greedy["rewards"]), 1)
        extra: dict[str, Any] = {}
        assign = records.get(("assign", robots))
        if assign and len(assign["rewards"]) == len(paired):
            ratios = np.array(assign["rewards"]) / np.maximum(np.array(greedy["rewards"]), 1)
            extra.update(assign_mean=assign["mean"], assign_sem=assign["sem"])
            extra.update(assign_paired_ratio=float(ratios.mean()))
        for kind in BOUNDS:  # the tightest last
            record = records.get((kind, robots))
            if record and len(record["rewards"]) == len(paired):
                extra[f"{kind}_bound"] = record["mean"]
                extra.update(
                    bound=kind,
                    gnn_of_bound=gnn["mean"] / record["mean"],
                    bound_over_greedy=record["mean"] / greedy["mean"],
                )
        rows.append(
            {
                "robots": robots,
                "waypoints": gnn.get("waypoints"),
                "episodes": len(paired),
                "greedy_mean": greedy["mean"],
                "greedy_sem": greedy["sem"],
                "gnn_mean": gnn["mean"],
                "gnn_sem": gnn["sem"],
                "greedy_per_robot": greedy["mean"] / robots,
                "gnn_per_robot": gnn["mean"] / robots,
                "ratio_of_means": gnn["mean"] / greedy["mean"],
                "paired_ratio_mean": float(paired.mean()),
                "paired_ratio_sem": float(paired.std(ddof=1) / np.sqrt(len(paired)))
                if len(paired) > 1
                else 0.0,
                **extra,
            }
        )
    return rows


def scale_table(rows: list[dict[str, Any]], path: Path) -> None:
    """Prints the rows of :func:`scale_rows` and writes them as CSV."""
    print(
        "| robots | waypoints | greedy | GNN | greedy / robot | GNN / robot | GNN / greedy "
        "| omniscient assignment (/ greedy) | bound (GNN's share, bound / greedy) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        assign, bound = "-", "-"
        if "assign_mean" in r:
            assign = (
                f"{r['assign_mean']:.1f} +- {r['assign_sem']:.1f} (x{r['assign_paired_ratio']:.3f})"
            )
        if "bound" in r:
            bound = (
                f"{r['bound']} {r[r['bound'] + '_bound']:.1f} ({100 * r['gnn_of_bound']:.0f}%, "
                f"x{r['bound_over_greedy']:.2f})"
            )
        print(
            f"| {r['robots']} | {r['waypoints']} | {r['greedy_mean']:.1f} +- {r['greedy_sem']:.1f}"
            f" | {r['gnn_mean']:.1f} +- {r['gnn_sem']:.1f} | {r['greedy_per_robot']:.2f} | "
            f"{r['gnn_per_robot']:.2f} | x{r['ratio_of_means']:.3f} (paired "
            f"{r['paired_ratio_mean']:.3f} +- {r['paired_ratio_sem']:.3f}) | {assign} | {bound} |"
        )
    if rows:
        header = list(dict.fromkeys(k for r in rows for k in r))
        lines = [",".join(header)] + [",".join(str(r.get(k, "")) for k in header) for r in rows]
        write_text_atomic(path, "\n".join(lines) + "\n")
        print(f"wrote {path}")


def scale_plot(rows: list[dict[str, Any]], path: Path, task: str) -> None:
    """Reward per robot and the GNN / greedy ratio against the team size."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    robots = [r["robots"] for r in rows]
    fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.5))
    for name, label in (("greedy", "greedy"), ("gnn", "GNN")):
        per_robot = [r[f"{name}_per_robot"] for r in rows]
        sem = [r[f"{name}_sem"] / r["robots"] for r in rows]
        left.errorbar(robots, per_robot, yerr=sem, marker="o", capsize=3, label=label)
    left.set_xscale("log")
    left.set_xlabel("robots (cities of 56.59 waypoints a robot)")
    left.set_ylabel("points visited per robot in 50 steps")
    left.legend()
    right.errorbar(
        robots,
        [r["paired_ratio_mean"] for r in rows],
        yerr=[r["paired_ratio_sem"] for r in rows],
        marker="o",
        capsize=3,
    )
    right.axhline(1.0, color="grey", lw=0.8)
    right.set_xscale("log")
    right.set_xlabel("robots")
    right.set_ylabel("GNN / greedy (paired seeds)")
    fig.suptitle(f"{task.capitalize()}: GNN beside greedy as the team grows (K = 19)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run(config: GeneralizeConfig) -> None:
    """Plays the missing results, prints the table, draws the plot."""
    import torch

    from marl_cover.agents.models.checkpoints import load_model
    from marl_cover.agents.models.shipped import default_model, model_path

    torch.set_num_threads(1)
    try:
        path = model_path(config.model or default_model(config.task))
        model, _ = load_model(path)
    except (FileNotFoundError, ValueError) as error:
        raise SystemExit(f"marl-cover generalize: {error}") from None
    sha = file_sha256(path)  # names the model in each result's setup
    out = Path(config.out)
    if not config.table_only:
        for robots in config.robots:
            for method in config.methods:
                result = out / f"{method}_R{robots}.json"
                if result.exists():
                    read_result(result, setup(method, robots, config, sha))
                else:
                    record = play(method, robots, config, model, sha)
                    write_text_atomic(result, json.dumps(record, indent=2))
                    print(f"done {method} R={robots}", flush=True)
    records = {
        (r["method"], r["robots"]): r for r in (read_json(p) for p in sorted(out.glob("*_R*.json")))
    }
    if config.map == "city":
        rows = scale_rows(records)
        scale_table(rows, out / "generalize.csv")
        if rows:
            scale_plot(rows, out / "generalize.png", config.task)
            print(f"wrote {out / 'generalize.png'}")
        return
    paper = paper_numbers(f"{config.task}_generalize_5659")
    table(records, paper)
    if records:
        plot(records, paper, out / "generalize.png", config.task)
        print(f"wrote {out / 'generalize.png'}")


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover generalize") -> None:
    """``marl-cover generalize``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    run(parse(GeneralizeConfig, args, prog=prog, description=__doc__ or ""))
