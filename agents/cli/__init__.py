"""The ``marl-cover`` command line: one subcommand a module, configs from typed dataclasses."""
