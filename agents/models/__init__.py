"""Graph neural network policies (needs the ``train`` extra: torch)."""

from marl_cover.agents.models.gnn import AggregationGNN, GNNConfig
from marl_cover.agents.models.logits import (
    centralized_logits,
    decentralized_logits,
    flatten_padded,
)

__all__ = [
    "AggregationGNN",
    "GNNConfig",
    "centralized_logits",
    "decentralized_logits",
    "flatten_padded",
]
