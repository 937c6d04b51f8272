"""Typed configs from YAML files and ``key=value`` overrides (dotted keys for nested sections).

Every config is a dataclass; a nested dataclass field is a section (``model.hops=19``). Unknown
keys are errors that name the key and the file or argument it came from.
"""

from __future__ import annotations

import dataclasses
import sys
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TypeVar

from agents.cli import parse_value
from marl_cover.config import check_values

T = TypeVar("T")


def _field_types(cls: type) -> dict[str, Any]:
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls)}


def build(cls: type[T], values: dict[str, Any], where: str = "config") -> T:
    """An instance of dataclass ``cls`` from a (nested) mapping.

    Raises:
        ValueError: an unknown key, a section that is not a mapping or a value of the wrong
            type (:func:`marl_cover.config.check_values`), naming it and ``where``.
    """
    if not isinstance(values, dict):
        raise ValueError(f"{where}: expected a mapping for {cls.__name__}, got {values!r}")
    types = _field_types(cls)
    unknown = sorted(set(values) - set(types))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; {cls.__name__} keys: {sorted(types)}")
    kwargs = {}
    for key, value in values.items():
        kind = types[key]
        if dataclasses.is_dataclass(kind) and isinstance(kind, type):
            kwargs[key] = build(kind, value, f"{where}.{key}")
        else:
            kwargs[key] = value
    try:
        check_values(cls, kwargs)  # before the constructor compares them
        return cls(**kwargs)
    except TypeError as error:
        raise ValueError(f"{where}: {error}") from error


def as_dict(config: Any) -> dict[str, Any]:
    """A config as plain nested dicts (for YAML, JSON and checkpoints)."""
    return dataclasses.asdict(config)


def apply_overrides(values: dict[str, Any], overrides: list[str]) -> dict[str, Any]:
    """``values`` with ``key=value`` / ``section.key=value`` arguments applied (a new dict).

    Raises:
        ValueError: an argument without ``=``, naming it.
    """
    result = {k: dict(v) if isinstance(v, dict) else v for k, v in values.items()}
    for argument in overrides:
        if "=" not in argument:
            raise ValueError(f"arguments are key=value overrides, got {argument!r}")
        key, text = argument.split("=", 1)
        *sections, name = key.split(".")
        target = result
        for section in sections:
            target = target.setdefault(section, {})
            if not isinstance(target, dict):
                raise ValueError(f"override {argument!r}: {section!r} is not a section")
        target[name] = parse_value(text)
    return result


def load(cls: type[T], path: str | Path | None = None, overrides: Sequence[str] = ()) -> T:
    """Config ``cls`` from its defaults, then the YAML file ``path``, then ``overrides``."""
    values: dict[str, Any] = as_dict(cls())
    where = "defaults"
    if path is not None:
        import yaml

        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"no config file at {path}")
        loaded = yaml.safe_load(path.read_text()) or {}
        if not isinstance(loaded, dict):
            raise ValueError(f"{path}: a config file must hold a mapping")
        build(cls, loaded, str(path))  # names unknown keys against the file
        values = merge(values, loaded)
        where = str(path)
    try:
        return build(cls, apply_overrides(values, list(overrides)), f"{where} + overrides")
    except TypeError as error:
        raise ValueError(f"bad override in {list(overrides)}: {error}") from error


def load_or_exit(cls: type[T], path: str | Path | None, overrides: list[str]) -> T:
    """:func:`load` for command lines: a bad file or override ends the script with one line
    that names the script and the problem (no traceback).

    Raises:
        SystemExit: the config cannot be loaded.
    """
    try:
        return load(cls, path, overrides)
    except (ValueError, FileNotFoundError) as error:
        raise SystemExit(f"{Path(sys.argv[0]).stem}: {error}") from error


def merge(base: dict[str, Any], update: dict[str, Any]) -> dict[str, Any]:
    """``base`` with ``update``'s values in place, section by section (a new dict)."""
    merged = dict(base)
    for key, value in update.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = merge(merged[key], value)
        else:
            merged[key] = value
    return merged
