"""The library's own errors, and the checks of the arguments every entry point shares.

Every file the library reads (maps, dataset shards and manifests, model files and cards,
configs) fails with :class:`BadFileError`, a ``ValueError`` that names the file and what is
wrong with it; a missing file raises :class:`MissingFileError`, which is both a
``BadFileError`` and a ``FileNotFoundError``. Catching ``BadFileError`` catches both.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np


class BadFileError(ValueError):
    """A file that cannot be used: corrupt, truncated, of another kind, or failing a check.

    Attributes:
        path: The file.
        problem: What is wrong with it, in words.
    """

    def __init__(self, path: str | os.PathLike[str], problem: str) -> None:
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")

    def __reduce__(self) -> tuple[Any, ...]:  # picklable across worker processes
        return (type(self), (self.path, self.problem))


class MissingFileError(BadFileError, FileNotFoundError):
    """A file the library needs is not there (also a ``FileNotFoundError``)."""


def as_node_indices(values: Any, name: str) -> np.ndarray:
    """``values`` as node indices ``(n,)`` int64, refusing anything that is not an integer.

    Args:
        values: A sequence or array of integers (booleans and floats are refused, integral
            or not: a float index is a bug upstream).
        name: The argument, as the message should name it.

    Raises:
        ValueError: naming ``name`` and its first entry that is not an integer.
    """
    array = np.asarray(values)
    if array.dtype.kind in "iu":
        return array.astype(np.int64).reshape(-1)
    flat = array.reshape(-1)
    if array.dtype.kind == "O":  # mixed Python objects: check each
        for i, value in enumerate(flat):
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
                where = _entry(i, array.shape)
                raise ValueError(f"{name} must hold integer indices; entry {where} is {value!r}")
        return flat.astype(np.int64)
    if flat.size == 0:
        return np.zeros(0, dtype=np.int64)
    first = 0
    if array.dtype.kind == "f":  # name the first entry that is not even integral
        fractional = np.flatnonzero(~np.isfinite(flat) | (flat != np.round(flat)))
        first = int(fractional[0]) if len(fractional) else 0
    raise ValueError(
        f"{name} must hold integer indices, got {array.dtype} values; "
        f"entry {_entry(first, array.shape)} is {flat[first].item()!r}"
    )


def _entry(flat_index: int, shape: tuple[int, ...]) -> str:
    """An entry's index as a user wrote it: ``3`` in a vector, ``(1, 0)`` in a table."""
    if len(shape) <= 1:
        return str(flat_index)
    return str(tuple(int(i) for i in np.unravel_index(flat_index, shape)))


def check_finite(values: np.ndarray, name: str) -> None:
    """Raises a ``ValueError`` naming ``name`` and its first row holding a NaN or infinity."""
    bad = ~np.isfinite(values)
    if bad.any():
        row = int(np.flatnonzero(bad.reshape(len(values), -1).any(axis=1))[0])
        raise ValueError(f"{name} must be finite; entry {row} is {values[row].tolist()}")
