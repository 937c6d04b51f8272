"""The aggregation GNN, its policies and checkpoints, and the shipped models.

Everything here needs the ``train`` extra (torch) except :mod:`.shipped`, which names the
shipped model files and reads their cards with the standard library alone; ``AggregationGNN``
and ``GNNConfig`` are imported from :mod:`.gnn` on first use.
"""

from __future__ import annotations

from typing import Any

__all__ = ["AggregationGNN", "GNNConfig"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        from marl_cover.agents.models import gnn

        return getattr(gnn, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
