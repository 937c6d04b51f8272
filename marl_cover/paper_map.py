"""The paper's urban map: where it is found, and how it is fetched and checked.

The paper's experiments run on ``grid_slice10.npy``, a ``(128, 110)`` boolean occupancy grid of
5 m cells. Its authors publish the same area at 1 m cells (``grid_slice2.npy``, ``(640, 554)``) in
their repository; ``grid_slice10`` is its 5 x 5 any-pooling. :func:`fetch_paper_map` downloads
the 1 m grid once (with pooch), checks its pinned SHA-256, derives the 5 m grid, checks that one
too and keeps both in the user cache directory.

:func:`paper_map_path` looks, in order, at ``$MARL_COVER_PAPER_MAP``, a ``shared/maps/`` folder
beside a source checkout, the cache, and finally downloads (unless ``$MARL_COVER_OFFLINE`` is
set). From the command line::

    marl-cover fetch-map        # fetch it now; prints the cached file's path

Environment variables:

=========================  ==========================================================
``MARL_COVER_PAPER_MAP``   path of a ``grid_slice10.npy`` to use instead of the cache
``MARL_COVER_CACHE``       cache folder (default: the platform's user cache, ``marl-cover``)
``MARL_COVER_OFFLINE``     any non-empty value: never download
=========================  ==========================================================
"""

from __future__ import annotations

import hashlib
import logging
import os
import tempfile
from pathlib import Path

import numpy as np

from marl_cover.errors import MissingFileError

logger = logging.getLogger(__name__)

PAPER_MAP_ENV = "MARL_COVER_PAPER_MAP"
CACHE_ENV = "MARL_COVER_CACHE"
OFFLINE_ENV = "MARL_COVER_OFFLINE"
#: The command that fetches the map, named by every error that asks for it.
FETCH_COMMAND = "marl-cover fetch-map"

#: The 5 m grid the experiments use, and its SHA-256 as a ``.npy`` file.
PAPER_MAP_NAME = "grid_slice10.npy"
PAPER_MAP_SHA256 = "1e80b5813d86ef768d56c7c7cd6e45b179a89b432a4c2f19ee7a5ca87d7075d0"
#: The authors' 1 m grid, pinned to one commit of their repository, and its SHA-256.
SOURCE_NAME = "grid_slice2.npy"
SOURCE_SHA256 = "bf86bef1c23a38334463b7904f2710c572dcf64b6812a14678a96e3916e87dd8"
SOURCE_URL = (
    "https://raw.githubusercontent.com/katetolstaya/gym-flock/"
    "871c8ee6962c04f146693fb4a0781ff0e89536ec/gym_flock/envs/spatial/maps/grid_slice2.npy"
)
#: Cells of the 1 m grid pooled into one 5 m cell, per axis.
POOL = 5


class PaperMapUnavailable(FileNotFoundError):
    """The paper's map is neither on disk nor downloadable (offline, or a bad download)."""


def sha256_of(path: str | os.PathLike[str]) -> str:
    """The SHA-256 of a file's bytes, as hex."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def cache_dir() -> Path:
    """The folder the fetched maps are kept in: ``$MARL_COVER_CACHE`` or the user cache."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    import pooch

    return Path(pooch.os_cache("marl-cover"))


def pool_occupancy(fine: np.ndarray, factor: int = POOL) -> np.ndarray:
    """Any-pooling of a boolean grid: a coarse cell is occupied when any of its fine cells is.

    Fine rows and columns past the last whole coarse cell are dropped (554 columns of 1 m cells
    make 110 cells of 5 m).

    Args:
        fine: ``(rows, cols)`` boolean grid.
        factor: fine cells per coarse cell, per axis.

    Returns:
        ``(rows // factor, cols // factor)`` boolean grid.
    """
    rows, cols = fine.shape[0] // factor, fine.shape[1] // factor
    blocks = np.asarray(fine, dtype=bool)[: rows * factor, : cols * factor]
    return np.asarray(blocks.reshape(rows, factor, cols, factor).any(axis=(1, 3)))


def npy_bytes(grid: np.ndarray) -> bytes:
    """``grid`` as ``.npy`` version 1.0 bytes with the header padded to 16 bytes.

    That is the layout of the published ``grid_slice10.npy`` (numpy now pads to 64), so the
    derived file has the published file's checksum.
    """
    grid = np.ascontiguousarray(grid)
    descr = np.lib.format.dtype_to_descr(grid.dtype)
    header = f"{{'descr': {descr!r}, 'fortran_order': False, 'shape': {grid.shape!r}, }}"
    prefix = b"\x93NUMPY\x01\x00"
    padding = -(len(prefix) + 2 + len(header) + 1) % 16
    text = (header + " " * padding + "\n").encode("latin1")
    return prefix + len(text).to_bytes(2, "little") + text + grid.tobytes()


def _write_atomic(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile(dir=path.parent, prefix=".tmp_", delete=False) as handle:
        temporary = Path(handle.name)
    try:
        temporary.write_bytes(data)
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def _checked_cached(path: Path, expected: str) -> bool:
    """Whether ``path`` holds the file of digest ``expected``; a wrong one is named in the log."""
    if not path.is_file():
        return False
    found = sha256_of(path)
    if found == expected:
        return True
    logger.warning(
        "%s: SHA-256 %s, expected %s (a corrupted cache); fetching it again", path, found, expected
    )
    return False


def fetch_paper_map(cache: str | os.PathLike[str] | None = None, url: str | None = None) -> Path:
    """The paper's ``grid_slice10.npy`` in the cache, downloaded and derived when missing.

    A cached file whose checksum is wrong is named in the log and made again.

    Args:
        cache: folder to keep the files in (default: :func:`cache_dir`).
        url: where to download ``grid_slice2.npy`` from (default: the authors' repository at
            the pinned commit, :data:`SOURCE_URL`).

    Returns:
        Path of the checked ``grid_slice10.npy``.

    Raises:
        PaperMapUnavailable: the download failed (naming the URL, :data:`FETCH_COMMAND` and
            ``$MARL_COVER_PAPER_MAP``) or gave a file of another checksum.
    """
    folder = Path(cache) if cache is not None else cache_dir()
    url = SOURCE_URL if url is None else url
    target = folder / PAPER_MAP_NAME
    if _checked_cached(target, PAPER_MAP_SHA256):
        return target
    source = folder / SOURCE_NAME
    if not _checked_cached(source, SOURCE_SHA256):
        _download(url, folder)
    grid = np.load(source, allow_pickle=False)
    data = npy_bytes(pool_occupancy(grid))
    found = hashlib.sha256(data).hexdigest()
    if found != PAPER_MAP_SHA256:  # cannot happen with the pinned source; say so if it does
        raise PaperMapUnavailable(
            f"{source}: pooling it {POOL}x{POOL} gives SHA-256 {found}, expected {PAPER_MAP_SHA256}"
        )
    _write_atomic(target, data)
    logger.info("the paper's map is at %s", target)
    return target


def _download(url: str, folder: Path) -> None:
    """Downloads ``url`` to ``folder / SOURCE_NAME``, checking its pinned SHA-256."""
    import pooch
    import requests

    help_text = (
        f"run `{FETCH_COMMAND}` when online, or set ${PAPER_MAP_ENV} to a copy of {PAPER_MAP_NAME}"
    )
    try:
        pooch.retrieve(
            url,
            known_hash=f"sha256:{SOURCE_SHA256}",
            fname=SOURCE_NAME,
            path=folder,
            progressbar=False,
        )
    except requests.RequestException as error:
        raise PaperMapUnavailable(
            f"the paper's map could not be downloaded from {url} ({error}); {help_text}"
        ) from None
    except ValueError as error:  # pooch: the download's checksum is not the pinned one
        raise PaperMapUnavailable(f"{url}: {error}; {help_text}") from None


def _checkout_copies() -> list[Path]:
    """Where a source checkout keeps the map: ``shared/maps/`` beside the repository root, then
    beside the working directory."""
    repo_root = Path(__file__).resolve().parent.parent
    return [
        repo_root.parent / "shared" / "maps" / PAPER_MAP_NAME,
        Path.cwd().parent / "shared" / "maps" / PAPER_MAP_NAME,
    ]


def paper_map_path() -> Path:
    """Location of the paper's ``grid_slice10.npy``, fetched on first use when online.

    Raises:
        MissingFileError: ``$MARL_COVER_PAPER_MAP`` names no file (naming it).
        PaperMapUnavailable: no copy was found and it cannot be downloaded, naming the places
            looked at, the command that fetches it, its URL and ``$MARL_COVER_PAPER_MAP``.
    """
    if os.environ.get(PAPER_MAP_ENV):
        chosen = Path(os.environ[PAPER_MAP_ENV])
        if not chosen.is_file():
            raise MissingFileError(chosen, f"${PAPER_MAP_ENV} names no file here")
        return chosen
    for path in _checkout_copies():
        if path.is_file():
            return path
    cached = cache_dir() / PAPER_MAP_NAME
    if _checked_cached(cached, PAPER_MAP_SHA256):
        return cached
    if os.environ.get(OFFLINE_ENV):
        tried = ", ".join(dict.fromkeys(str(p) for p in [*_checkout_copies(), cached]))
        raise PaperMapUnavailable(
            f"the paper's map {PAPER_MAP_NAME} was not found (tried {tried}) and "
            f"${OFFLINE_ENV} forbids downloading it from {SOURCE_URL}; run `{FETCH_COMMAND}` "
            f"when online, or set ${PAPER_MAP_ENV} to its path"
        )
    return fetch_paper_map()
