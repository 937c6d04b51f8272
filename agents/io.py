"""Files and progress shared by the commands and training loops: atomic writes, content
digests, progress bars, and results that are read back on resume only when they were made
under the same setup."""

from __future__ import annotations

import functools
import hashlib
import json
import os
import sys
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from marl_cover.errors import BadFileError, MissingFileError


def progress_bar(
    desc: str, unit: str = "episode", leave: bool = True
) -> Callable[..., Iterable[Any]] | None:
    """A wrapper that shows an iteration's progress on stderr (tqdm), or ``None`` when tqdm is
    not installed (the ``dev`` and ``train`` extras have it)."""
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return functools.partial(tqdm, desc=desc, unit=unit, file=sys.stderr, leave=leave)


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


def read_json(path: str | Path) -> Any:
    """The JSON document in a file.

    Raises:
        MissingFileError: no file at ``path``.
        BadFileError: the file is not UTF-8 JSON, naming it, the line and the column.
    """
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(path, "no such file")
    try:
        return json.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as error:
        raise BadFileError(path, f"not UTF-8 text ({error})") from None
    except json.JSONDecodeError as error:
        raise BadFileError(path, f"not JSON ({error})") from None


def file_sha256(path: str | Path) -> str:
    """The SHA-256 of a file's bytes (names a model file by its content, not its path)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def read_result(path: str | Path, setup: dict[str, Any]) -> dict[str, Any]:
    """A finished result (a JSON object with its ``"setup"``), read back to resume a job.

    A file that records no setup (written before setups were recorded) is reused with a note.

    Raises:
        BadFileError: the file is not a JSON object, or was made under another setup, naming
            it and the keys that differ.
    """
    path = Path(path)
    result = read_json(path)
    if not isinstance(result, dict):
        raise BadFileError(path, "not a result (a JSON object)")
    recorded = result.get("setup")
    setup = json.loads(json.dumps(setup))  # as it reads back (lists, not tuples)
    if recorded is None:
        print(f"note: {path} does not record its setup; reused as it is", flush=True)
    elif recorded != setup:
        differ = sorted(k for k in set(recorded) | set(setup) if recorded.get(k) != setup.get(k))
        raise BadFileError(
            path,
            f"made under another setup (differs in {differ}); "
            "delete it or choose another output folder",
        )
    return result
