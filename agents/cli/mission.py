"""The paper's quadrotor mission: discrete policies flying robots with dynamics, zero-shot.

Ten quadrotor-like robots on the paper's 1266-waypoint graph for 400 s of mission time (the
``mission`` preset); greedy, the routing expert and the GNN (``model=``, the shipped
``gnn_mission`` by default), paired over the seeds. Writes, under ``out``:
``runs/<method>_<seed>.json`` per mission (read back when present and flown under the same
setup, so an interrupted run resumes), ``mission.json`` (the table), ``mission.png`` (points of
interest visited over time, mean +- SEM) and ``mission_gnn.gif`` (one GNN mission).

Example::

    marl-cover mission seeds=3 methods=[greedy,gnn] dynamics.retarget=rate
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from marl_cover.agents.cli.options import as_dict, parse
from marl_cover.agents.evaluation.comparison import sem
from marl_cover.agents.io import read_result, write_bytes_atomic, write_text_atomic
from marl_cover.agents.mission.flight import (
    MissionConfig,
    MissionResult,
    make_mission_policy,
    run_mission,
)

PAPER = {"greedy": 490, "gnn": 610}  # points visited in 400 s (paper, Sec. VI)


def fly_all(config: MissionConfig, out: Path) -> dict[str, list[dict]]:
    """Every (method, seed) mission, read back when already done."""
    env = config.make_env()
    results: dict[str, list[dict]] = {}
    for method in config.methods:
        policy = None
        results[method] = []
        setup = config.setup(method)
        for seed in range(config.seed, config.seed + config.seeds):
            path = out / "runs" / f"{method}_{seed}.json"
            if path.is_file():
                try:
                    results[method].append(read_result(path, setup))
                except ValueError as error:  # made under another setup: named, no traceback
                    raise SystemExit(f"marl-cover mission: {error}") from None
                continue
            policy = policy or make_mission_policy(method, config)
            result = {**run_mission(env, policy, seed).as_dict(), "setup": setup}
            write_text_atomic(path, json.dumps(result))
            results[method].append(result)
            print(
                f"{method:12s} seed {seed:3d}: {result['total']:4d} / {result['num_interest']} "
                f"points, {result['near_misses']} near-misses, "
                f"{result['real_time_factor']:.0f}x real time",
                flush=True,
            )
    return results


def table(config: MissionConfig, results: dict[str, list[dict]]) -> dict:
    """Per-seed totals, means, ratios to greedy and speed, printed and returned."""
    seeds = list(range(config.seed, config.seed + config.seeds))
    totals = {m: np.array([r["total"] for r in rs], dtype=float) for m, rs in results.items()}
    print(f"\npoints of interest visited in {config.dynamics.max_time:.0f} s, per seed")
    print("seed  " + "".join(f"{m:>12s}" for m in totals))
    for i, seed in enumerate(seeds):
        print(f"{seed:4d}  " + "".join(f"{totals[m][i]:12.0f}" for m in totals))
    summary: dict = {"config": as_dict(config), "seeds": seeds, "methods": {}}
    horizon = len(results[next(iter(results))][0]["visited"]) - 1
    times = list(range(0, horizon + 1, max(1, horizon // 8)))
    print("\npoints of interest visited over time (mean over the seeds)")
    print("time (s)  " + "".join(f"{m:>12s}" for m in totals))
    for t in times:
        means = [np.mean([r["visited"][t] for r in results[m]]) for m in totals]
        print(f"{t:8d}  " + "".join(f"{v:12.1f}" for v in means))
    summary["over_time"] = {
        "seconds": times,
        **{
            m: [float(np.mean([r["visited"][t] for r in results[m]])) for t in times]
            for m in totals
        },
    }
    print("\nmethod        mean +- SEM    ratio to greedy (paired)   real time x (min)  paper")
    for method, values in totals.items():
        speed = np.array([r["real_time_factor"] for r in results[method]])
        entry = {
            "totals": values.tolist(),
            "mean": float(values.mean()),
            "sem": sem(values),
            "real_time_factor_min": float(speed.min()),
            "real_time_factor_median": float(np.median(speed)),
            "near_misses": int(sum(r["near_misses"] for r in results[method])),
            "paper": PAPER.get(method),
        }
        ratio_text = ""
        if "greedy" in totals and method != "greedy":
            ratios = values / totals["greedy"]
            entry["ratio_to_greedy"] = {
                "of_means": float(values.mean() / totals["greedy"].mean()),
                "per_seed_mean": float(ratios.mean()),
                "per_seed_sem": sem(ratios),
                "per_seed_min": float(ratios.min()),
            }
            ratio_text = f"{ratios.mean():.3f} +- {sem(ratios):.3f} (min {ratios.min():.2f})"
        summary["methods"][method] = entry
        print(
            f"{method:12s} {values.mean():6.1f} +- {sem(values):5.1f}   {ratio_text:26s} "
            f"{np.median(speed):6.0f} ({speed.min():.0f})      {PAPER.get(method, '')}"
        )
    return summary


def plot(config: MissionConfig, results: dict[str, list[dict]], path: Path) -> None:
    """Points of interest visited over time, mean +- SEM per method, beside the paper's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4), dpi=120)
    for method, runs in results.items():
        curves = np.array([r["visited"] for r in runs], dtype=float)  # (seeds, seconds + 1)
        mean = curves.mean(axis=0)
        err = curves.std(axis=0, ddof=1) / np.sqrt(len(curves)) if len(curves) > 1 else 0 * mean
        t = np.arange(curves.shape[1])
        ax.plot(t, mean, label=method)
        ax.fill_between(t, mean - err, mean + err, alpha=0.25)
    for method, value in PAPER.items():
        ax.scatter([config.dynamics.max_time], [value], marker="x", color="black")
        ax.annotate(f"paper {method}", (config.dynamics.max_time, value), fontsize=7)
    ax.set_xlabel("mission time (s)")
    ax.set_ylabel("points of interest visited")
    ax.set_title(f"{config.num_robots} quadrotors, {config.map}, {config.seeds} seeds")
    ax.legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


def animate(config: MissionConfig, seed: int, path: Path) -> None:
    """One GNN mission as a GIF (robots at their true positions, 20 s trails)."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    from marl_cover.render import draw_map, figure_to_array

    env = config.make_env()
    result: MissionResult = run_mission(
        env, make_mission_policy("gnn", config), seed, config.frame_every
    )
    snapshot = env.snapshot()
    fig, ax = plt.subplots(figsize=(6, 6), dpi=80)
    history = np.array([f[1][:, :2] for f in result.frames])  # (F, R, 2)
    trail = max(1, round(20.0 / config.frame_every))
    images = []
    for k, (time, positions, visited) in enumerate(result.frames):
        ax.clear()
        draw_map(
            ax,
            snapshot.graph,
            env.targets,
            snapshot.interest,
            visited,
            robot_xy=positions[:, :2],
            trail_xy=history[max(0, k - trail) : k + 1],
        )
        ax.set_title(f"GNN, t = {time:5.1f} s, visited {int(visited.sum())}")
        images.append(
            Image.fromarray(figure_to_array(fig)).convert("P", palette=Image.Palette.ADAPTIVE)
        )
    plt.close(fig)
    buffer = io.BytesIO()
    images[0].save(buffer, format="GIF", save_all=True, append_images=images[1:], duration=100)
    write_bytes_atomic(path, buffer.getvalue())


def run(config: MissionConfig) -> dict:
    """Flies the missing missions, prints the table, writes the JSON, the plot and the GIF."""
    import torch

    torch.set_num_threads(1)
    out = Path(config.out)
    results = fly_all(config, out)
    summary = table(config, results)
    write_text_atomic(out / "mission.json", json.dumps(summary, indent=1))
    plot(config, results, out / "mission.png")
    if config.animate_seed is not None and "gnn" in config.methods:
        animate(config, config.animate_seed, out / "mission_gnn.gif")
    print(
        f"\nwrote {out}/mission.json, mission.png"
        + (", mission_gnn.gif" if config.animate_seed is not None else "")
    )
    return summary


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover mission") -> None:
    """``marl-cover mission``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    config = parse(
        MissionConfig,
        args,
        prog=prog,
        description=__doc__ or "",
        preset="mission",
        presets=["mission"],
    )
    run(config)
