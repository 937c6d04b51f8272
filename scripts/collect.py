"""``marl-cover collect`` as a script (``python scripts/collect.py --help``)."""

from marl_cover.agents.cli.collect import main

if __name__ == "__main__":
    main(prog="scripts/collect.py")
