"""``marl-cover``: one command line for every job of the library.

    marl-cover --help                     # the subcommands
    marl-cover evaluate --help            # every option of one, with its type and default
    marl-cover evaluate policy=gnn env.map=paper episodes=10

Each subcommand lives in a module of :mod:`marl_cover.agents.cli` with a typed config dataclass
and a ``main(argv)``; it is imported only when it runs, so ``marl-cover --help`` needs neither
torch nor a solver.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

#: Subcommand -> (module of marl_cover.agents.cli, one line on what it does).
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("demo", "the shipped GNN beside greedy and the expert on fresh cities, and a GIF"),
    "evaluate": ("evaluate", "any policy over fixed, paired episode seeds: JSON and CSV"),
    "compare": ("compare", "paired comparison of evaluation CSVs or missions"),
    "collect": ("collect", "expert episodes into a resumable dataset of shards"),
    "train-bc": ("train_bc", "behaviour cloning of the expert, with DAgger rounds"),
    "train-mappo": ("train_mappo", "MAPPO / IPPO with TorchRL on the batched environment"),
    "average": ("average", "the weight average of a run's last snapshots, chosen on seeds"),
    "sweep": ("sweep", "one behaviour-cloning run per (kind, K)"),
    "grid": ("grid", "an evaluation grid (policies x K x maps x teams): one CSV, one plot"),
    "generalize": ("generalize", "10..100 robots on the 5659-waypoint map, GNN beside greedy"),
    "reproduce-paper": ("reproduce_paper", "the paper's K sweeps beside its published numbers"),
    "mission": ("mission", "the quadrotor mission: discrete policies flying robots"),
    "inspect": ("inspect", "one robot's ego-graph: its sizes, and a PNG"),
    "plot-mappo": ("plot_mappo", "learning curves of MAPPO runs"),
    "bench": ("bench_env", "environment throughput: env steps/s and agent-steps/s"),
    "bench-gnn": ("bench_gnn", "GNN controller time per step, beside the paper's"),
    "bench-mission": ("bench_mission", "the mission's real-time factor"),
    "bench-scale": ("bench_scale", "large teams: 4 to 10,000 robots, POGEMA, the GNN at 1000"),
    "bench-scale-out": ("bench_scale_out", "serial beside 1 and 2 Ray workers: eval, data, MAPPO"),
    "fuzz": ("fuzz", "random maps, teams and bad actions, the env's invariants checked"),
    "fetch-map": ("fetch_map", "download and check the paper's map into the user cache"),
}


#: Optional package -> the extra that installs it.
EXTRAS = {
    "torch": "train",
    "torchrl": "train",
    "tensordict": "train",
    "pyvrp": "expert",
    "ortools": "expert",
    "matplotlib": "render",
    "networkx": "render",
    "PIL": "render",
    "numba": "fast",
    "ray": "ray",
}


def usage() -> str:
    """The top-level help: the subcommands, one line each."""
    width = max(map(len, COMMANDS))
    lines = [f"  {name:<{width}}  {about}" for name, (_, about) in COMMANDS.items()]
    return (
        "usage: marl-cover COMMAND [--config NAME] [key=value ...] [--flag value ...]\n\n"
        "Multi-robot coverage and exploration on spatial graphs.\n\ncommands:\n"
        + "\n".join(lines)
        + "\n\n`marl-cover COMMAND --help` lists every option of a command, with its type and "
        "default."
    )


def main(argv: Sequence[str] | None = None) -> None:
    """Runs ``marl-cover COMMAND ...`` (``argv``: the arguments after the program name)."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help", "help"):
        print(usage())
        return
    if args[0] == "--version":
        from marl_cover import __version__

        print(f"marl-cover {__version__}")
        return
    name, rest = args[0], args[1:]
    if name not in COMMANDS:
        raise SystemExit(f"marl-cover: unknown command {name!r}; commands: {', '.join(COMMANDS)}")
    try:
        module = importlib.import_module(f"marl_cover.agents.cli.{COMMANDS[name][0]}")
        module.main(rest, prog=f"marl-cover {name}")
    except ModuleNotFoundError as error:  # an optional package the command needs
        top = (error.name or "").split(".")[0]
        if top not in EXTRAS:
            raise
        raise SystemExit(
            f"marl-cover {name} needs {top}: pip install 'marl-cover[{EXTRAS[top]}]'"
        ) from None


if __name__ == "__main__":
    main()
