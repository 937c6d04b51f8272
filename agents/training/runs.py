"""What every training run shares: its command line, its folder's config check and its TorchRL
logger."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from agents.configuration import merge

LOGGERS = ("csv", "tensorboard", "none")


def check_same_run(
    path: Path,
    record: dict[str, Any],
    ignored: Iterable[str] = (),
    defaults: dict[str, Any] | None = None,
) -> None:
    """Refuses to resume the run whose ``config.yaml`` is ``path`` with other settings.

    Args:
        path: The run's saved config (nothing to check if it does not exist yet).
        record: The new run's config as plain dicts.
        ignored: Keys that may change between sessions (progress bars, lengths): top-level
            names, or ``section.key`` for one key of a section.
        defaults: The config's default values as plain dicts: a key that the saved config
            lacks (a run made before the key existed) reads as its default.

    Raises:
        ValueError: another key differs; the message names the keys and the folder.
    """
    import yaml

    if not path.exists():
        return
    saved = yaml.safe_load(path.read_text()) or {}
    previous = _flatten(merge(defaults or {}, saved))
    current = _flatten(yaml.safe_load(yaml.safe_dump(record)))  # as it reads back: tuples as lists
    skip = set(ignored)
    changed = sorted(
        key
        for key in set(previous) | set(current)
        if not skip.intersection(_prefixes(key)) and previous.get(key) != current.get(key)
    )
    if changed:
        raise ValueError(
            f"{path.parent} holds a run with other settings ({changed}); use another out= or "
            "delete the folder"
        )


def _flatten(values: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"a": {"b": 1}}`` as ``{"a.b": 1}``, at any depth."""
    flat = {}
    for key, value in values.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict) and value:
            flat.update(_flatten(value, f"{name}."))
        else:
            flat[name] = value
    return flat


def _prefixes(key: str) -> list[str]:
    """``"a.b.c"`` -> ``["a", "a.b", "a.b.c"]``."""
    parts = key.split(".")
    return [".".join(parts[: i + 1]) for i in range(len(parts))]


def make_logger(kind: str, out: Path) -> Any:
    """A TorchRL logger writing under ``out/log`` (``None`` for ``"none"``)."""
    if kind not in LOGGERS:
        raise ValueError(f"logger must be one of {LOGGERS}, got {kind!r}")
    if kind == "none":
        return None
    if kind == "tensorboard":
        from torchrl.record.loggers import TensorboardLogger

        return TensorboardLogger(exp_name="log", log_dir=str(out))
    from torchrl.record.loggers import CSVLogger

    return CSVLogger(exp_name="log", log_dir=str(out))


def command_line(
    argv: list[str],
    doc: str,
    config_class: type[Any],
    default_config: Path,
    train: Callable[[Any], dict[str, Any]],
) -> None:
    """A training script's ``main``: ``[--config YAML] key=value ...`` -> the typed config ->
    ``train(config)`` -> its summary as JSON on stdout.

    ``--help`` shows the script's docstring (its examples); ``--print-config`` prints the
    settings a run would use, as YAML that ``--config`` reads back, and trains nothing. Bad
    settings (an unknown key, a missing file, a bad value) exit with a one-line message that
    names the script and the problem.
    """
    import argparse
    import json
    import logging
    import sys

    import yaml

    from agents import configuration

    parser = argparse.ArgumentParser(
        description=doc, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--config", default=str(default_config), help="YAML preset")
    parser.add_argument(
        "--print-config",
        action="store_true",
        help="print the resolved settings as YAML and exit without training",
    )
    parser.add_argument("overrides", nargs="*", help="key=value overrides")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    script = Path(sys.argv[0]).stem
    try:
        config = configuration.load(config_class, args.config, args.overrides)
        if args.print_config:
            print(yaml.safe_dump(configuration.as_dict(config), sort_keys=False), end="")
            return
        import torchrl  # noqa: F401 (configures its logger on import; quieten it after)

        logging.getLogger("torchrl").setLevel(logging.WARNING)  # it logs buffer set-up to stdout
        summary = train(config)
    except (ValueError, FileNotFoundError) as error:
        raise SystemExit(f"{script}: {error}") from error
    print(json.dumps(summary, indent=2, default=str))
