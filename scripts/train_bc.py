"""``marl-cover train-bc`` as a script (``python scripts/train_bc.py --help``)."""

from marl_cover.agents.cli.train_bc import main

if __name__ == "__main__":
    main(prog="scripts/train_bc.py")
