"""Download the paper's map, check it, derive the 5 m grid and keep both in the user cache.

The authors' ``grid_slice2.npy`` (1 m cells) is fetched from their repository at a pinned
commit, its SHA-256 checked, pooled 5 x 5 to ``grid_slice10.npy`` (checked too) and cached; a
cached file of the wrong checksum is named and fetched again. Prints the cached file's path.
``map="paper"`` does the same on its first use when online (:mod:`marl_cover.paper_map`).

Example::

    marl-cover fetch-map
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Sequence
from dataclasses import dataclass

from marl_cover.agents.cli.options import parse
from marl_cover.paper_map import SOURCE_URL, PaperMapUnavailable, fetch_paper_map


@dataclass
class FetchMapConfig:
    """Where from, and where to."""

    cache: str | None = None  # the cache folder (None: $MARL_COVER_CACHE or the user cache)
    url: str = SOURCE_URL  # where grid_slice2.npy is downloaded from


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover fetch-map") -> None:
    """``marl-cover fetch-map``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    config = parse(FetchMapConfig, args, prog=prog, description=__doc__ or "")
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        print(fetch_paper_map(config.cache, config.url))
    except PaperMapUnavailable as error:
        raise SystemExit(f"{prog}: {error}") from None
