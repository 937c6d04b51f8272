"""``marl-cover evaluate`` as a script (``python scripts/evaluate.py --help``)."""

from marl_cover.agents.cli.evaluate import main

if __name__ == "__main__":
    main(prog="scripts/evaluate.py")
