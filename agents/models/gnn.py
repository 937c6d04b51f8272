"""Aggregation graph neural networks of the paper, in plain torch, shared by every robot.

Two models (``GNNConfig.kind``):

- ``"linear"`` (the paper's "identity" aggregation GNN): node and edge encoders, then ``hops``
  weightless diffusion steps (each edge takes its sender's latent, each node the mean of its
  incoming edges' latents), an edge decoder applied after every step.
- ``"nonlinear"``: the same encoder and decoder around ``hops`` applications of one shared
  graph-network block: an edge MLP on ``[e, h_receiver, h_sender]`` and a node MLP on
  ``[mean of incoming edges, h]``.

The decoded edge latents of every stage are concatenated and a linear readout gives one logit
per edge; a robot's action logits are those of its five action edges (target -> robot), and a
masked categorical over them is its policy. Aggregation is ``index_add_`` over a flat graph:
a batch of padded graphs is flattened with node offsets, and padded edges are dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from marl_cover.ego import NUM_ACTIONS, NUM_NODE_FEATURES

KINDS = ("linear", "nonlinear")


@dataclass(frozen=True)
class GNNConfig:
    """Shape of an aggregation GNN (defaults: the paper's non-linear model at K = 19).

    Attributes:
        kind: ``"linear"`` or ``"nonlinear"``.
        hops: Message-passing steps K (the receptive field).
        hidden: Width of every MLP and latent.
        mlp_layers: Linear layers per MLP (ReLU after all but the last).
        node_features: Input node features.
        edge_features: Input edge features.
    """

    kind: str = "nonlinear"
    hops: int = 19
    hidden: int = 16
    mlp_layers: int = 3
    node_features: int = NUM_NODE_FEATURES
    edge_features: int = 1

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}, got {self.kind!r}")
        if self.hops < 1 or self.hidden < 1 or self.mlp_layers < 1:
            raise ValueError("hops, hidden and mlp_layers must be >= 1")


def mlp(inputs: int, hidden: int, layers: int) -> nn.Sequential:
    """``layers`` linear layers of width ``hidden``, ReLU after all but the last."""
    modules: list[nn.Module] = []
    for i in range(layers):
        modules.append(nn.Linear(inputs if i == 0 else hidden, hidden))
        if i < layers - 1:
            modules.append(nn.ReLU())
    return nn.Sequential(*modules)


def mean_aggregate(
    messages: torch.Tensor, receivers: torch.Tensor, num_nodes: int, inverse_degree: torch.Tensor
) -> torch.Tensor:
    """Mean of ``messages (E, H)`` at each receiver, ``(num_nodes, H)`` (0 without edges)."""
    total = messages.new_zeros(num_nodes, messages.shape[1]).index_add_(0, receivers, messages)
    return total * inverse_degree


class AggregationGNN(nn.Module):
    """One logit per edge of a graph of robots and waypoints (see the module docstring)."""

    def __init__(self, config: GNNConfig | None = None) -> None:
        super().__init__()
        self.config = config = config or GNNConfig()
        h, layers = config.hidden, config.mlp_layers
        self.node_encoder = mlp(config.node_features, h, layers)
        self.edge_encoder = mlp(config.edge_features, h, layers)
        self.edge_decoder = mlp(h, h, layers)
        if config.kind == "nonlinear":
            self.edge_block = mlp(3 * h, h, layers)
            self.node_block = mlp(2 * h, h, layers)
        self.readout = nn.Linear((config.hops + 1) * h, 1)
        nn.init.orthogonal_(self.readout.weight)
        nn.init.zeros_(self.readout.bias)

    def forward(
        self, nodes: torch.Tensor, edge_index: torch.Tensor, edge_attr: torch.Tensor
    ) -> torch.Tensor:
        """Edge logits of one flat graph.

        Args:
            nodes: ``(V, node_features)`` float.
            edge_index: ``(2, E)`` long, ``[sender; receiver]``.
            edge_attr: ``(E, edge_features)`` float.

        Returns:
            ``(E,)`` logits.
        """
        senders, receivers = edge_index[0], edge_index[1]
        num_nodes = nodes.shape[0]
        degree = torch.bincount(receivers, minlength=num_nodes).clamp(min=1)
        inverse_degree = (1.0 / degree.to(nodes.dtype)).unsqueeze(1)
        h = self.node_encoder(nodes)
        e = self.edge_encoder(edge_attr)
        stages = [self.edge_decoder(e)]
        for _ in range(self.config.hops):
            if self.config.kind == "linear":
                e = h[senders]
                h = mean_aggregate(e, receivers, num_nodes, inverse_degree)
            else:
                e = self.edge_block(torch.cat([e, h[receivers], h[senders]], dim=1))
                h = self.node_block(
                    torch.cat([mean_aggregate(e, receivers, num_nodes, inverse_degree), h], 1)
                )
            stages.append(self.edge_decoder(e))
        return self.readout(torch.cat(stages, dim=1)).squeeze(1)


def flatten_padded(batch: dict[str, torch.Tensor]) -> tuple[torch.Tensor, ...]:
    """A batch of padded graphs ``(B, M, ...)`` as one flat graph without padded edges.

    Returns:
        ``nodes (B*M, F)``, ``edge_index (2, E')``, ``edge_attr (E', 1)``, and the flat edge
        id of each graph's first five edges, ``(B, 5)`` (``-1`` where padded).
    """
    nodes, edge_index = batch["nodes"], batch["edge_index"]
    num_graphs, num_nodes = nodes.shape[:2]
    num_edges = edge_index.shape[2]
    keep = batch["edge_mask"].reshape(-1).bool()
    offsets = (torch.arange(num_graphs, device=nodes.device) * num_nodes).view(-1, 1, 1)
    flat_index = (edge_index.long() + offsets).permute(1, 0, 2).reshape(2, -1)[:, keep]
    flat_attr = batch["edge_attr"].reshape(-1, batch["edge_attr"].shape[-1])[keep]
    new_id = torch.cumsum(keep.long(), 0) - 1
    heads = (torch.arange(num_graphs, device=nodes.device) * num_edges).view(-1, 1)
    heads = heads + torch.arange(NUM_ACTIONS, device=nodes.device)
    action_edges = torch.where(keep[heads], new_id[heads], torch.full_like(heads, -1))
    return nodes.reshape(-1, nodes.shape[-1]), flat_index, flat_attr, action_edges


def action_logits(edge_logits: torch.Tensor, action_edges: torch.Tensor) -> torch.Tensor:
    """Logits of each robot's five actions ``(R, 5)``; ``-inf`` where an edge id is ``-1``."""
    picked = edge_logits[action_edges.clamp(min=0)]
    return picked.masked_fill(action_edges < 0, float("-inf"))


def decentralized_logits(model: AggregationGNN, batch: dict[str, torch.Tensor]) -> torch.Tensor:
    """Action logits ``(B, 5)`` of each ego robot from its padded ego-graph (node 0)."""
    nodes, edge_index, edge_attr, action_edges = flatten_padded(batch)
    return action_logits(model(nodes, edge_index, edge_attr), action_edges)


def centralized_logits(model: AggregationGNN, state: dict[str, torch.Tensor]) -> torch.Tensor:
    """Action logits ``(R, 5)`` of every robot from one pass over ``state()``."""
    num_robots = state["robot_nodes"].shape[-1]
    batch = {k: v.unsqueeze(0) for k, v in state.items() if k != "robot_nodes"}
    nodes, edge_index, edge_attr, _ = flatten_padded(batch)
    keep = state["edge_mask"].bool()
    new_id = torch.cumsum(keep.long(), 0) - 1
    heads = torch.arange(NUM_ACTIONS * num_robots, device=keep.device).view(num_robots, -1)
    action_edges = torch.where(keep[heads], new_id[heads], torch.full_like(heads, -1))
    return action_logits(model(nodes, edge_index, edge_attr), action_edges)
