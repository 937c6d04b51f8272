"""``marl-cover generalize`` as a script (``python scripts/generalize.py --help``)."""

from marl_cover.agents.cli.generalize import main

if __name__ == "__main__":
    main(prog="scripts/generalize.py")
