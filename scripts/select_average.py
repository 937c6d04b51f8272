"""Chooses how many of a run's last snapshots to average, on selection seeds; writes the average.

    python scripts/select_average.py RUN [--sizes 1 5 7 9] [--task coverage] [--map paper]
        [--num-robots R] [--max-steps T] [--episodes 100] [--seed 10000] [--out RUN/average]
    e.g.  python scripts/select_average.py outputs/bc/explore_from_cov_perhop8 \\
        --task exploration --sizes 1 5 7 9 13
    e.g.  python scripts/select_average.py outputs/bc/mission_standin --map paper_full \\
        --num-robots 10 --max-steps 131 --episodes 20 --seed 100     # the mission's stand-in

``RUN`` is a behaviour-cloning or MAPPO run trained with ``snapshots=true`` (its ``steps/``
folder). For each size ``n``, the mean of the last ``n`` snapshots plays one episode per seed
(``--seed`` .. ``--seed + --episodes - 1``, the selection seeds, never the test seeds 0..99); the
table gives each window's mean reward and its paired difference with the best, which is written
to ``OUT/average.pt`` (a model file, ``scripts/evaluate.py checkpoint=OUT/average.pt``; its
metadata names the averaged files and the scores), beside ``OUT/selection.json``. Per-window
results are kept in ``OUT/windows/``: an interrupted call resumes, and a second call with more
sizes plays only the new windows (see :mod:`agents.averaging`).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.averaging import load_window, select_window  # noqa: E402
from agents.cli import positive_int, progress_bar, write_text_atomic  # noqa: E402
from marl_cover.config import TASKS  # noqa: E402


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="a run folder with steps/step_NNNNNN.pt")
    parser.add_argument("--sizes", type=positive_int, nargs="+", default=[1, 3, 5, 7, 9])
    parser.add_argument("--task", choices=list(TASKS), default="coverage")
    parser.add_argument("--map", default="paper")
    parser.add_argument("--num-robots", type=positive_int, default=None, help="default: the env's")
    parser.add_argument("--max-steps", type=positive_int, default=None, help="default: the env's")
    parser.add_argument("--episodes", type=positive_int, default=100)
    parser.add_argument("--seed", type=int, default=10000)
    parser.add_argument("--out", type=Path, default=None, help="default: RUN/average")
    args = parser.parse_args(argv)
    out = args.out or args.run / "average"
    env_kwargs = {"map": args.map, "task": args.task}
    if args.num_robots is not None:
        env_kwargs["num_robots"] = args.num_robots
    if args.max_steps is not None:
        env_kwargs["max_steps"] = args.max_steps
    seeds = list(range(args.seed, args.seed + args.episodes))
    progress = progress_bar("episodes", leave=False)
    try:
        results, best = select_window(
            args.run, args.sizes, env_kwargs, seeds, out / "windows", progress
        )
    except (FileNotFoundError, ValueError) as error:
        raise SystemExit(str(error)) from error
    team = "".join(
        f", {key} {env_kwargs[key]}" for key in ("num_robots", "max_steps") if key in env_kwargs
    )
    print(f"{args.task} on {args.map}{team}, seeds {seeds[0]}..{seeds[-1]}")
    print(f"{'window':<28} {'mean':>7} {'SEM':>6} {'vs best':>16}")
    for result in results:
        diff, sem = result.paired(best)
        mark = "  <- best" if result is best else ""
        print(
            f"{result.name:<28} {result.mean:7.2f} {result.sem:6.2f} "
            f"{diff:+8.2f} +- {sem:4.2f}{mark}"
        )
    model, metadata = load_window(best.files)
    selection = {
        "seeds": f"{seeds[0]}..{seeds[-1]}",
        "env": env_kwargs,
        "chosen": best.name,
        "windows": {r.name: {"mean": round(r.mean, 3), "sem": round(r.sem, 3)} for r in results},
        "command": "python scripts/select_average.py "
        + " ".join(sys.argv[1:] if argv is None else argv),
    }
    from agents.models.policy import save_model

    save_model(out / "average.pt", model, {**metadata, "selection": selection})
    write_text_atomic(out / "selection.json", json.dumps(selection, indent=1))
    print(f"wrote {out / 'average.pt'} ({best.name}) and {out / 'selection.json'}")


if __name__ == "__main__":
    main()
