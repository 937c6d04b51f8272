"""``marl-cover bench-gnn`` as a script (``python scripts/bench_gnn.py --help``)."""

from marl_cover.agents.cli.bench_gnn import main

if __name__ == "__main__":
    main(prog="scripts/bench_gnn.py")
