"""Critics: aggregation GNNs that read a robot's value off its stay edge.

The critic is an :class:`~agents.models.gnn.AggregationGNN` of its own (no weights shared with
the actor) whose output on a robot's stay edge (action slot 0, waypoint -> robot, present at
every step) is that robot's value:

- :class:`StateValue` (MAPPO): one pass over the whole-graph ``state`` gives every robot's
  value, ``(..., R, 1)``; ``aggregate="sum"`` gives the paper's team value ``sum_r v_r``
  (``reference_impl.md`` section 3) at every robot instead.
- :class:`EgoValue` (IPPO): each robot's value from its own ego-graph, ``(..., 1)``.

With ``horizon`` (the episode length), both also read ``steps_left`` (the state's actions left)
and give the network ``steps_left / horizon`` as one more feature of every node: in a
fixed-length episode the same graph is worth less when fewer steps are left, which the graph
alone does not tell.
"""

from __future__ import annotations

import torch
from torch import nn

from agents.models.gnn import AggregationGNN, flatten_padded, with_time_feature
from agents.models.policy import flat_batch
from marl_cover.ego import NUM_ACTIONS

AGGREGATES = ("robot", "sum")


class StateValue(nn.Module):
    """Values ``(..., R, 1)`` of every robot from padded states ``(..., M, *)``.

    Args:
        gnn: The critic network.
        num_robots: Robots per state (the state's first ``5 R`` edges are their action edges).
        aggregate: ``"robot"``: each robot's own output; ``"sum"``: the sum over the team,
            repeated for every robot.
        horizon: Episode length; given, ``forward`` takes ``steps_left`` and ``gnn`` reads one
            node feature more than the observations have.
    """

    def __init__(
        self,
        gnn: AggregationGNN,
        num_robots: int,
        aggregate: str = "robot",
        horizon: int | None = None,
    ) -> None:
        super().__init__()
        if aggregate not in AGGREGATES:
            raise ValueError(f"aggregate must be one of {AGGREGATES}, got {aggregate!r}")
        if horizon is not None and horizon < 1:
            raise ValueError(f"horizon must be >= 1, got {horizon}")
        self.gnn = gnn
        self.num_robots = num_robots
        self.aggregate = aggregate
        self.horizon = horizon

    def forward(
        self,
        nodes: torch.Tensor,
        edge_index: torch.Tensor,
        edge_attr: torch.Tensor,
        edge_mask: torch.Tensor,
        node_mask: torch.Tensor,
        steps_left: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Value ``(..., R, 1)`` of every robot from padded states ``(..., M, *)``."""
        if (steps_left is None) != (self.horizon is None):
            raise ValueError("steps_left must be given exactly when the critic has a horizon")
        if steps_left is not None and self.horizon is not None:
            nodes = with_time_feature(nodes, steps_left, self.horizon)
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

    def __init__(self, gnn: AggregationGNN, horizon: int | None = None) -> None:
        super().__init__(gnn, num_robots=1, horizon=horizon)

    def forward(
        self,
        nodes: torch.Tensor,
        edge_index: torch.Tensor,
        edge_attr: torch.Tensor,
        edge_mask: torch.Tensor,
        node_mask: torch.Tensor,
        steps_left: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Value ``(..., 1)`` of each ego robot from its padded ego-graph ``(..., M, *)``."""
        values = super().forward(nodes, edge_index, edge_attr, edge_mask, node_mask, steps_left)
        return values.squeeze(-2)
