"""Action logits from padded graphs: batches flattened into one graph, the five action edges
of each robot read out, and the time feature for models that read the clock."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch

from marl_cover.ego import NUM_ACTIONS, NUM_NODE_FEATURES, STAY

if TYPE_CHECKING:
    from marl_cover.agents.models.gnn import AggregationGNN
    from marl_cover.compact import CompactObservations


def with_time_feature(nodes: torch.Tensor, steps_left: torch.Tensor, horizon: int) -> torch.Tensor:
    """``nodes (*B, ..., M, F)`` with ``steps_left (*B,) / horizon`` appended to every node,
    ``(*B, ..., M, F + 1)``."""
    fraction = steps_left.to(nodes.dtype) / horizon
    fraction = fraction.reshape(*fraction.shape, *([1] * (nodes.dim() - fraction.dim())))
    return torch.cat([nodes, fraction.expand(*nodes.shape[:-1], 1)], dim=-1)


def timed_nodes(model: AggregationGNN, batch: dict[str, torch.Tensor]) -> torch.Tensor:
    """``batch["nodes"]`` with the time feature when ``model`` reads one.

    Raises:
        KeyError: the model reads the time but ``batch`` has no ``steps_left``.
    """
    horizon = model.config.time_horizon
    if horizon is None:
        return batch["nodes"]
    if "steps_left" not in batch:
        raise KeyError(
            f"this model reads the time (time_horizon={horizon}) but the input has no "
            "'steps_left' (the actions left in the episode)"
        )
    return with_time_feature(batch["nodes"], batch["steps_left"], horizon)


def flatten_padded(
    batch: dict[str, torch.Tensor], num_heads: int = NUM_ACTIONS
) -> tuple[torch.Tensor, ...]:
    """A batch of padded graphs ``(B, M, ...)`` as one flat graph without padded edges.

    With a ``node_mask`` (real nodes are a prefix of each graph), node padding beyond the
    largest graph of the batch is cut off too: real edges never touch it, so the outputs are
    unchanged and a large padded shape costs nothing.

    Args:
        batch: Padded graph arrays with a leading batch axis.
        num_heads: Leading edges of each graph whose flat ids are returned (the five action
            edges of an ego-graph; ``5 R`` for a state's robots).

    Returns:
        ``nodes (B*M', F)`` with ``M' <= M``, ``edge_index (2, E')``, ``edge_attr (E', 1)``,
        and the flat edge id of each graph's first ``num_heads`` edges, ``(B, num_heads)``
        (``-1`` where padded).
    """
    nodes, edge_index = batch["nodes"], batch["edge_index"]
    if "node_mask" in batch and nodes.shape[1] > 0:
        num_real = int(batch["node_mask"].reshape(nodes.shape[0], -1).sum(1).max())
        nodes = nodes[:, : max(num_real, 1)]
    num_graphs, num_nodes = nodes.shape[:2]
    num_edges = edge_index.shape[2]
    keep = batch["edge_mask"].reshape(-1).bool()
    offsets = (torch.arange(num_graphs, device=nodes.device) * num_nodes).view(-1, 1, 1)
    flat_index = (edge_index.long() + offsets).permute(1, 0, 2).reshape(2, -1)[:, keep]
    flat_attr = batch["edge_attr"].reshape(-1, batch["edge_attr"].shape[-1])[keep]
    new_id = torch.cumsum(keep.long(), 0) - 1
    heads = (torch.arange(num_graphs, device=nodes.device) * num_edges).view(-1, 1)
    heads = heads + torch.arange(num_heads, device=nodes.device)
    action_edges = torch.where(keep[heads], new_id[heads], torch.full_like(heads, -1))
    return nodes.reshape(-1, nodes.shape[-1]), flat_index, flat_attr, action_edges


def action_logits(
    model: AggregationGNN,
    graph: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
    action_edges: torch.Tensor,
) -> torch.Tensor:
    """Logits ``(R, 5)`` of the action edges ``(R, 5)`` of a flat graph; ``-inf`` where ``-1``."""
    picked = model(*graph, out_edges=action_edges.clamp(min=0).reshape(-1))
    logits = picked.view(action_edges.shape)
    if model.stay_logit is not None:  # (GNNConfig.stay_bias) added to the stay slot only
        slot = torch.zeros(NUM_ACTIONS, dtype=logits.dtype, device=logits.device)
        slot[STAY] = 1.0
        logits = logits + slot * model.stay_logit.to(logits.dtype)
    return logits.masked_fill(action_edges < 0, float("-inf"))


def decentralized_logits(model: AggregationGNN, batch: dict[str, torch.Tensor]) -> torch.Tensor:
    """Action logits ``(B, 5)`` of each ego robot from its padded ego-graph (node 0) (and its
    ``steps_left (B,)`` when the model reads the time)."""
    batch = {**batch, "nodes": timed_nodes(model, batch)}
    nodes, edge_index, edge_attr, action_edges = flatten_padded(batch)
    return action_logits(model, (nodes, edge_index, edge_attr), action_edges)


def compact_logits(
    model: AggregationGNN, tables: CompactObservations, dtype: torch.dtype = torch.float32
) -> torch.Tensor:
    """Action logits ``(R, 5)`` of every robot from its own ego-graph, read from compact
    step-wide tables (:class:`marl_cover.compact.CompactObservations`) in one pass over their
    disjoint union: the decentralized controller, without padding (``-inf`` where an action
    has no edge)."""
    nodes_np, edge_index_np, edge_attr_np = tables.flat_graph()
    nodes = torch.from_numpy(np.ascontiguousarray(nodes_np[:, :NUM_NODE_FEATURES])).to(dtype)
    horizon = model.config.time_horizon
    if horizon is not None:
        per_node = np.repeat(tables.steps_left, np.diff(tables.node_offsets))  # (V,)
        nodes = with_time_feature(nodes, torch.from_numpy(per_node), horizon)
    graph = (
        nodes,
        torch.from_numpy(np.ascontiguousarray(edge_index_np)),
        torch.from_numpy(edge_attr_np).to(dtype),
    )
    return action_logits(model, graph, torch.from_numpy(tables.action_edges()))


def centralized_logits(model: AggregationGNN, state: dict[str, torch.Tensor]) -> torch.Tensor:
    """Action logits ``(R, 5)`` of every robot from one pass over ``state()``."""
    batch = {k: v.unsqueeze(0) for k, v in state.items() if k != "robot_nodes"}
    return batched_state_logits(model, batch, state["robot_nodes"].shape[-1])[0]


def batched_state_logits(
    model: AggregationGNN, batch: dict[str, torch.Tensor], num_robots: int
) -> torch.Tensor:
    """Action logits ``(B, R, 5)`` of every robot of a batch of padded states ``(B, M, ...)``,
    one pass over all of them (``-inf`` where an action has no edge; ``steps_left (B,)`` when
    the model reads the time)."""
    batch = {**batch, "nodes": timed_nodes(model, batch)}
    nodes, edge_index, edge_attr, heads = flatten_padded(batch, NUM_ACTIONS * num_robots)
    logits = action_logits(model, (nodes, edge_index, edge_attr), heads.view(-1, NUM_ACTIONS))
    return logits.view(heads.shape[0], num_robots, NUM_ACTIONS)
