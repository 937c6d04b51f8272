"""What every training run shares: its folder's config check and its TorchRL logger."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

LOGGERS = ("csv", "tensorboard", "none")


def check_same_run(path: Path, record: dict[str, Any], ignored: Iterable[str] = ()) -> None:
    """Refuses to resume the run whose ``config.yaml`` is ``path`` with other settings.

    Args:
        path: The run's saved config (nothing to check if it does not exist yet).
        record: The new run's config as plain dicts.
        ignored: Top-level keys that may change between sessions (progress bars, lengths).

    Raises:
        ValueError: another key differs; the message names the keys and the folder.
    """
    import yaml

    if not path.exists():
        return
    previous = yaml.safe_load(path.read_text()) or {}
    changed = sorted(
        k
        for k in set(previous) | set(record)
        if k not in set(ignored) and previous.get(k) != record.get(k)
    )
    if changed:
        raise ValueError(
            f"{path.parent} holds a run with other settings ({changed}); use another out= or "
            "delete the folder"
        )


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
