"""What every training run shares: its folder's config check and its TorchRL logger."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

from marl_cover.errors import BadFileError

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
        ignored: Keys that may change between the legs of a run (progress bars, lengths): top-level
            names, or ``section.key`` for one key of a section.
        defaults: The config's default values as plain dicts: a key that the saved config
            lacks (a run made before the key existed) reads as its default.

    Raises:
        ValueError: another key differs; the message names the keys and the folder.
        BadFileError: the saved settings are not a YAML mapping, naming the file.
    """
    import yaml
    from omegaconf import OmegaConf

    if not path.exists():
        return
    try:
        saved = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    except (yaml.YAMLError, UnicodeDecodeError) as error:
        problem = " ".join(str(error).split())
        raise BadFileError(path, f"not a run's YAML settings ({problem})") from None
    if not isinstance(saved, dict):
        raise BadFileError(path, "not a run's YAML settings (not a mapping)")
    merged = OmegaConf.merge(OmegaConf.create(defaults or {}), OmegaConf.create(saved))
    previous = _flatten(OmegaConf.to_container(merged))  # type: ignore[arg-type]
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
