"""Graph neural network policies (needs the ``train`` extra: torch)."""

from agents.models.gnn import (
    AggregationGNN,
    GNNConfig,
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
