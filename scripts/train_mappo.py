"""``marl-cover train-mappo`` as a script (``python scripts/train_mappo.py --help``)."""

from marl_cover.agents.cli.train_mappo import main

if __name__ == "__main__":
    main(prog="scripts/train_mappo.py")
