"""``marl-cover fuzz`` as a script (``python scripts/fuzz_env.py --help``)."""

from marl_cover.agents.cli.fuzz import main

if __name__ == "__main__":
    main(prog="scripts/fuzz_env.py")
