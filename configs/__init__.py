"""YAML presets of the command line's configs, found by name: ``marl-cover train-mappo --config
mappo_finetune``."""
