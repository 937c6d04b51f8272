"""``marl-cover demo`` as a script (``python scripts/demo.py --help``)."""

from marl_cover.agents.cli.demo import main

if __name__ == "__main__":
    main(prog="scripts/demo.py")
