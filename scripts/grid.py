"""``marl-cover grid`` as a script (``python scripts/grid.py --help``)."""

from marl_cover.agents.cli.grid import main

if __name__ == "__main__":
    main(prog="scripts/grid.py")
