"""Critics: aggregation GNNs that read a robot's value off its stay edge.

The critic is an :class:`~marl_cover.agents.models.gnn.AggregationGNN` of its own (no weights shared
with the actor) whose output on a robot's stay edge (action slot 0, waypoint -> robot, present at
every step) is that robot's value:

- :class:`StateValue` (MAPPO): one pass over the whole-graph ``state`` gives every robot's
  value, ``(..., R, 1)``; ``aggregate="sum"`` gives the paper's team value ``sum_r v_r``
  (the paper's code) at every robot instead.
- :class:`EgoValue` (IPPO): each robot's value from its own ego-graph, ``(..., 1)``.
"""

from __future__ import annotations

import torch
from torch import nn

from marl_cover.agents.models.actors import flat_batch
from marl_cover.agents.models.gnn import AggregationGNN
from marl_cover.agents.models.logits import flatten_padded
from marl_cover.ego import NUM_ACTIONS

AGGREGATES = ("robot", "sum")


class StateValue(nn.Module):
    """Values ``(..., R, 1)`` of every robot from padded states ``(..., M, *)``.

    Args:
        gnn: The critic network.
        num_robots: Robots per state (the state's first ``5 R`` edges are their action edges).
        aggregate: ``"robot"``: each robot's own output; ``"sum"``: the sum over the team,
            repeated for every robot.
    """

    def __init__(self, gnn: AggregationGNN, num_robots: int, aggregate: str = "robot") -> None:
        super().__init__()
        if aggregate not in AGGREGATES:
            raise ValueError(f"aggregate must be one of {AGGREGATES}, got {aggregate!r}")
        self.gnn = gnn
        self.num_robots = num_robots
        self.aggregate = aggregate

    def forward(
        self,
        nodes: torch.Tensor,
        edge_index: torch.Tensor,
        edge_attr: torch.Tensor,
        edge_mask: torch.Tensor,
        node_mask: torch.Tensor,
    ) -> torch.Tensor:
        """Value ``(..., R, 1)`` of every robot from padded states ``(..., M, *)``."""
        lead, r = nodes.shape[:-2], self.num_robots
        batch = flat_batch(nodes, edge_index, edge_attr, edge_mask, node_mask)
        flat_nodes, flat_index, flat_attr, heads = flatten_padded(batch, NUM_ACTIONS * r)
        stay = heads.view(-1, r, NUM_ACTIONS)[..., 0]  # (B, R), always a real edge
        values = self.gnn(flat_nodes, flat_index, flat_attr, out_edges=stay.reshape(-1))
        values = values.view(-1, r, 1)
        if self.aggregate == "sum":
            values = values.sum(dim=1, keepdim=True).expand(-1, r, 1)
        return values.reshape(*lead, r, 1)


class EgoValue(StateValue):
    """Value ``(..., 1)`` of each ego robot from its padded ego-graph ``(..., M, *)`` (laid
    out as a state with one robot, the ego)."""

    def __init__(self, gnn: AggregationGNN) -> None:
        super().__init__(gnn, num_robots=1)

    def forward(
        self,
        nodes: torch.Tensor,
        edge_index: torch.Tensor,
        edge_attr: torch.Tensor,
        edge_mask: torch.Tensor,
        node_mask: torch.Tensor,
    ) -> torch.Tensor:
        """Value ``(..., 1)`` of each ego robot from its padded ego-graph ``(..., M, *)``."""
        values = super().forward(nodes, edge_index, edge_attr, edge_mask, node_mask)
        return values.squeeze(-2)
