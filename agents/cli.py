"""Helpers shared by the scripts and training loops: ``key=value`` values, argparse types for
counts and seeds, atomic writes, progress bars, and results that are read back on resume only
when they were made under the same setup."""

from __future__ import annotations

import argparse
import functools
import hashlib
import json
import math
import os
import sys
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any


def progress_bar(
    desc: str, unit: str = "episode", leave: bool = True
) -> Callable[[Iterable[Any]], Iterable[Any]] | None:
    """A wrapper that shows an iteration's progress on stderr (tqdm), or ``None`` when tqdm is
    not installed (the ``dev`` and ``train`` extras have it)."""
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return functools.partial(tqdm, desc=desc, unit=unit, file=sys.stderr, leave=leave)


def parse_value(text: str) -> Any:
    """``true``/``false``, ``none``/``null``, integers, floats and ``[a,b,...]`` lists of them;
    anything else stays text."""
    if text.startswith("[") and text.endswith("]"):
        inner = text[1:-1].strip()
        return [parse_value(item.strip()) for item in inner.split(",")] if inner else []
    lowered = text.lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    if lowered in ("none", "null"):
        return None
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return text


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1 (counts: robots, episodes, hops, steps)."""
    return _checked(text, int, lambda value: value >= 1, "an integer >= 1")


def non_negative_int(text: str) -> int:
    """argparse type: an integer >= 0 (seeds)."""
    return _checked(text, int, lambda value: value >= 0, "an integer >= 0")


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0 (seconds)."""
    return _checked(text, float, lambda value: 0 < value < math.inf, "a number > 0")


def _checked(text: str, cast: type, accept: Callable[[Any], bool], expected: str) -> Any:
    try:
        value = cast(text)
    except ValueError:
        value = None
    if value is None or not accept(value):
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
    return value


def write_bytes_atomic(path: str | Path, data: bytes) -> Path:
    """Writes ``data`` to a temporary file beside ``path``, then renames it into place."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile(dir=path.parent, prefix=".tmp_", delete=False) as handle:
        temporary = Path(handle.name)
        try:
            handle.write(data)
        except BaseException:
            handle.close()
            temporary.unlink(missing_ok=True)
            raise
    temporary.chmod(0o644)
    os.replace(temporary, path)
    return path


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Writes ``text`` (UTF-8) atomically, as :func:`write_bytes_atomic`."""
    return write_bytes_atomic(path, text.encode("utf-8"))


def file_sha256(path: str | Path) -> str:
    """The SHA-256 of a file's bytes (names a model file by its content, not its path)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def read_result(path: str | Path, setup: dict[str, Any]) -> dict[str, Any]:
    """A finished result (a JSON object with its ``"setup"``), read back to resume a job.

    A file that records no setup (written before setups were recorded) is reused with a note.

    Raises:
        ValueError: the file was made under another setup, naming it and the keys that differ.
    """
    path = Path(path)
    result = json.loads(path.read_text())
    recorded = result.get("setup")
    setup = json.loads(json.dumps(setup))  # as it reads back (lists, not tuples)
    if recorded is None:
        print(f"note: {path} does not record its setup; reused as it is", flush=True)
    elif recorded != setup:
        differ = sorted(k for k in set(recorded) | set(setup) if recorded.get(k) != setup.get(k))
        raise ValueError(
            f"{path} was made under another setup (differs in {differ}); "
            "delete it or choose another output folder"
        )
    return result
