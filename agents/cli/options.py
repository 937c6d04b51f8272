"""Typed configs from presets, ``key=value`` overrides and ``--flags``.

Every command's settings are one dataclass; a nested dataclass is a section (``model.hops=19``).
A command line is read in three layers, each over the one before:

1. the dataclass's defaults, or a YAML preset (``--config mappo_finetune``: a preset shipped in
   :mod:`marl_cover.configs`, or the path of a YAML file);
2. ``key=value`` / ``section.key=value`` overrides, merged by OmegaConf against the
   dataclass's schema (an unknown key or a value of the wrong type is an error that names it);
3. ``--key value`` flags, parsed by tyro, which also writes ``--help`` (every option with its
   type and default) from the dataclass's fields and docstrings.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from typing import Any, TypeVar

from marl_cover.errors import BadFileError

T = TypeVar("T")

#: The package whose YAML files are the presets ``--config NAME`` finds.
PRESET_PACKAGE = "marl_cover.configs"


class ConfigError(ValueError):
    """A preset, an override or a value that does not fit a config, naming it."""


class ConfigFileError(BadFileError, ConfigError):
    """A config file that cannot be read, or whose keys or values do not fit the config."""


def preset_names() -> list[str]:
    """The names of the shipped presets (``--config NAME``)."""
    folder = resources.files(PRESET_PACKAGE)
    return sorted(
        p.name.removesuffix(".yaml") for p in folder.iterdir() if p.name.endswith(".yaml")
    )


def preset_path(name: str | Path) -> Path:
    """The YAML file of a preset name, or ``name`` itself when it is a file.

    Raises:
        ConfigError: ``name`` is neither a file nor a shipped preset, naming the presets.
    """
    path = Path(name)
    if path.is_file():
        return path
    shipped = resources.files(PRESET_PACKAGE) / f"{path.name.removesuffix('.yaml')}.yaml"
    if shipped.is_file():
        return Path(str(shipped))
    raise ConfigError(f"no config file or preset {str(name)!r}; presets: {preset_names()}")


def as_dict(config: Any) -> dict[str, Any]:
    """A config as plain nested dicts (for YAML, JSON and checkpoints)."""
    return dataclasses.asdict(config)


def to_yaml(config: Any) -> str:
    """A config as YAML that ``--config`` reads back."""
    import yaml

    return yaml.safe_dump(as_dict(config), sort_keys=False)


def load(cls: type[T], config: str | Path | None = None, overrides: Sequence[str] = ()) -> T:
    """Config ``cls`` from its defaults, then the preset or file ``config``, then ``overrides``.

    Args:
        cls: The config dataclass.
        config: A preset name or a YAML file (``None``: the defaults).
        overrides: ``key=value`` / ``section.key=value`` strings (values read as YAML:
            ``[1,2]``, ``null``, ``true``).

    Raises:
        ConfigError: a key is unknown, a value has the wrong type or is out of range; the
            message names the file or the argument. A file that is not a YAML mapping, or
            whose keys or values do not fit, raises its subclass :class:`ConfigFileError` (a
            :class:`~marl_cover.errors.BadFileError` too).
    """
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    merged = OmegaConf.structured(cls)
    if config is not None:
        path = preset_path(config)
        try:
            loaded = OmegaConf.load(path)
        except Exception as error:  # noqa: BLE001 (YAML errors come in many types)
            problem = " ".join(str(error).split())
            raise ConfigFileError(path, f"not a YAML mapping ({problem})") from None
        try:
            merged = _merge(merged, loaded, str(path))
        except ConfigError as error:
            raise ConfigFileError(path, str(error).removeprefix(f"{path}: ")) from None
    bad = [item for item in overrides if "=" not in item]
    if bad:
        raise ConfigError(f"overrides are key=value, got {bad}")
    merged = _merge(merged, OmegaConf.from_dotlist(list(overrides)), f"overrides {list(overrides)}")
    try:
        return OmegaConf.to_object(merged)  # type: ignore[return-value]
    except OmegaConfBaseException as error:
        raise ConfigError(_message(error, "config")) from None
    except (TypeError, ValueError, FileNotFoundError) as error:  # the dataclasses' own checks
        where = f"{config}: " if config is not None else ""
        raise ConfigError(f"{where}{error}") from None


def _merge(base: Any, update: Any, where: str) -> Any:
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    try:
        return OmegaConf.merge(base, update)
    except OmegaConfBaseException as error:
        raise ConfigError(_message(error, where)) from None
    except (TypeError, ValueError) as error:
        raise ConfigError(f"{where}: {error}") from None


def _message(error: Exception, where: str) -> str:
    """OmegaConf's message in one line: the problem and the key."""
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    key = next((line for line in lines if line.startswith("full_key:")), "")
    return f"{where}: {lines[0] if lines else error}" + (f" ({key})" if key else "")


def split_argv(argv: Sequence[str]) -> tuple[str | None, bool, list[str], list[str]]:
    """``argv`` as ``(preset, print_config, key=value overrides, --flags)``."""
    preset, print_config = None, False
    overrides: list[str] = []
    flags: list[str] = []
    items = list(argv)
    while items:
        item = items.pop(0)
        if item == "--config":
            if not items:
                raise ConfigError("--config needs a preset name or a YAML file")
            preset = items.pop(0)
        elif item.startswith("--config="):
            preset = item.removeprefix("--config=")
        elif item == "--print-config":
            print_config = True
        elif not item.startswith("-") and "=" in item and item.split("=", 1)[0]:
            overrides.append(item)
        else:
            flags.append(item)
    return preset, print_config, overrides, flags


def parse(
    cls: type[T],
    argv: Sequence[str],
    *,
    prog: str,
    description: str,
    preset: str | None = None,
    presets: Sequence[str] = (),
) -> T:
    """A command's config from its command line (see the module docstring).

    ``--config NAME`` replaces ``preset`` (the command's default preset, if any; ``presets``:
    the prefixes of the preset names that ``--help`` lists as this command's);
    ``--print-config`` prints the resolved settings as YAML and exits; ``--help`` lists every
    option with its type and default.

    Raises:
        SystemExit: ``--help``, ``--print-config``, or a bad preset, override or flag (a
            one-line message that names the command and the problem).
    """
    import tyro

    try:
        chosen, print_config, overrides, flags = split_argv(argv)
        default = load(cls, chosen or preset, overrides)
    except ConfigError as error:
        raise SystemExit(f"{prog}: {error}") from None
    names = [name for name in preset_names() if name.startswith(tuple(presets))] if presets else []
    listed = f" (presets: {', '.join(names)})" if names else ""
    default_preset = f"; default: --config {preset}" if preset else ""
    usage = (
        f"{description.strip()}\n\nSettings, each layer over the one before: --config "
        f"NAME|FILE{listed}{default_preset}; then key=value overrides (section.key=value); "
        "then the --flags below. --print-config prints the resolved settings as YAML."
    )
    try:
        config = tyro.cli(
            cls,
            args=flags,
            default=default,
            prog=prog,
            description=usage,
            config=(tyro.conf.FlagConversionOff,),
            use_underscores=True,
        )
    except (TypeError, ValueError, FileNotFoundError) as error:  # the dataclasses' own checks
        raise SystemExit(f"{prog}: {error}") from None
    if print_config:
        print(to_yaml(config), end="")
        raise SystemExit(0)
    return config


def command_name() -> str:
    """The running command's name for messages (``marl-cover evaluate``, or the script's)."""
    return Path(sys.argv[0]).stem if sys.argv and sys.argv[0] else "marl-cover"
