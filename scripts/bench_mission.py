"""``marl-cover bench-mission`` as a script (``python scripts/bench_mission.py --help``)."""

from marl_cover.agents.cli.bench_mission import main

if __name__ == "__main__":
    main(prog="scripts/bench_mission.py")
