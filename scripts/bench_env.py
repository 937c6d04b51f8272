"""``marl-cover bench`` as a script (``python scripts/bench_env.py --help``)."""

from marl_cover.agents.cli.bench_env import main

if __name__ == "__main__":
    main(prog="scripts/bench_env.py")
