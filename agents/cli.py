"""Helpers shared by the command-line scripts: ``key=value`` values and atomic writes."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any


def parse_value(text: str) -> Any:
    """``true``/``false``, ``none``/``null``, integers and floats; anything else stays text."""
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


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Writes ``text`` to a temporary file beside ``path``, then renames it into place."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile(
        "w", dir=path.parent, delete=False, suffix=".tmp", newline=""
    ) as handle:
        handle.write(text)
    os.replace(handle.name, path)
    return path
