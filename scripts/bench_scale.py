"""``marl-cover bench-scale`` as a script (``python scripts/bench_scale.py --help``)."""

from marl_cover.agents.cli.bench_scale import main

if __name__ == "__main__":
    main(prog="scripts/bench_scale.py")
