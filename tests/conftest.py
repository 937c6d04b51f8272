"""Shared fixtures: tiny hand-built graphs and the paper's map (read from ../shared/maps)."""

from __future__ import annotations

import os
import tempfile

import numpy as np
import pytest

from marl_cover.graph import SpatialGraph
from marl_cover.maps import paper_map_path

# No test downloads anything, and none writes into the user's cache; scripts run as
# subprocesses inherit both.
os.environ["MARL_COVER_OFFLINE"] = "1"
os.environ.setdefault("MARL_COVER_CACHE", tempfile.mkdtemp(prefix="marl_cover_cache_"))

try:  # scatter ops slow down tenfold with two threads on the CI machines
    import torch

    torch.set_num_threads(1)
except ImportError:  # torch is an optional extra
    pass


@pytest.fixture
def tee_graph() -> SpatialGraph:
    """Six waypoints, cell size 1::

    5
    |
    4
    |
    0 - 1 - 2 - 3
    """
    positions = [(0, 0), (1, 0), (2, 0), (3, 0), (1, 1), (1, 2)]
    edges = [(0, 1), (1, 2), (2, 3), (1, 4), (4, 5)]
    return SpatialGraph.from_edges(np.array(positions, float), edges, cell_size=1.0)


@pytest.fixture
def path_graph() -> SpatialGraph:
    """Eight waypoints in a row, 0 (west) to 7 (east), cell size 5 m."""
    positions = np.stack([np.arange(8) * 5.0, np.zeros(8)], axis=1)
    return SpatialGraph.from_edges(positions, [(i, i + 1) for i in range(7)], cell_size=5.0)


@pytest.fixture(scope="session")
def paper_map_available() -> None:
    try:
        paper_map_path()
    except FileNotFoundError as error:
        pytest.skip(str(error))
