"""``marl-cover bench-scale-out`` as a script (``python scripts/bench_scale_out.py --help``)."""

from marl_cover.agents.cli.bench_scale_out import main

if __name__ == "__main__":
    main(prog="scripts/bench_scale_out.py")
