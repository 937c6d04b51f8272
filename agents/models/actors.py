"""The GNN as TensorDict modules for the training loops (TorchRL).

- :class:`EgoGraphLogits` maps padded ego-graph observations (any leading batch shape, such as
  ``(robots,)`` or ``(envs, robots)``) to action logits and a boolean action mask;
  :func:`make_actor` wraps it as a TorchRL ``ProbabilisticActor`` with a ``MaskedCategorical``
  (the module that behaviour cloning and MAPPO share).
- :class:`StateLogits` / :func:`make_state_actor` give every robot's logits from one pass over
  each whole-graph state (the same numbers, for the training loops).
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

from marl_cover.agents.models.gnn import AggregationGNN
from marl_cover.agents.models.logits import batched_state_logits
from marl_cover.ego import NUM_ACTIONS

#: Keys of a padded graph observation read by the policy.
GRAPH_KEYS = ("nodes", "edge_index", "edge_attr", "edge_mask", "action_mask")


class StateLogits(nn.Module):
    """Action logits ``(..., R, 5)`` and mask ``(..., R, 5)`` bool of every robot from padded
    states ``(..., M, *)`` (whose first ``5 R`` edges are the robots' action edges).

    One pass over each state gives every robot's logits: the same numbers as
    :class:`EgoGraphLogits` on the robots' ego-graphs (the ego-graph holds the network's whole
    receptive field), for about ``1 / R`` of the work; training loops use it. Masked actions
    get logit 0 (finite, so that entropies and gradients stay clean); the mask output is what a
    ``MaskedCategorical`` must read.
    """

    def __init__(self, gnn: AggregationGNN, num_robots: int) -> None:
        super().__init__()
        self.gnn = gnn
        self.num_robots = num_robots

    def forward(
        self,
        nodes: torch.Tensor,
        edge_index: torch.Tensor,
        edge_attr: torch.Tensor,
        edge_mask: torch.Tensor,
        node_mask: torch.Tensor | None,
        action_mask: torch.Tensor,
        steps_left: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Logits and mask ``(..., R, 5)`` of padded states ``(..., M, *)`` (class docstring)."""
        lead, r = nodes.shape[:-2], self.num_robots
        batch = flat_batch(nodes, edge_index, edge_attr, edge_mask, node_mask)
        if steps_left is not None:  # (*lead,): read when the network has a time_horizon
            batch["steps_left"] = steps_left.reshape(-1)
        logits = batched_state_logits(self.gnn, batch, r)  # (B, R, 5), -inf without an edge
        mask = action_mask.reshape(-1, r, NUM_ACTIONS).bool() & torch.isfinite(logits)
        logits = logits.masked_fill(~mask, 0.0)
        return logits.view(*lead, r, NUM_ACTIONS), mask.view(*lead, r, NUM_ACTIONS)


class EgoGraphLogits(StateLogits):
    """Action logits ``(..., 5)`` and mask ``(..., 5)`` bool of each ego robot from its padded
    ego-graph ``(..., M, *)``: an ego-graph is laid out as a state with one robot, the ego."""

    def __init__(self, gnn: AggregationGNN) -> None:
        super().__init__(gnn, num_robots=1)

    def forward(  # type: ignore[override]
        self,
        nodes: torch.Tensor,
        edge_index: torch.Tensor,
        edge_attr: torch.Tensor,
        edge_mask: torch.Tensor,
        action_mask: torch.Tensor,
        steps_left: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Logits and mask ``(..., 5)`` of padded ego-graphs ``(..., M, *)``."""
        logits, mask = super().forward(
            nodes, edge_index, edge_attr, edge_mask, None, action_mask.unsqueeze(-2), steps_left
        )
        return logits.squeeze(-2), mask.squeeze(-2)


def flat_batch(
    nodes: torch.Tensor,
    edge_index: torch.Tensor,
    edge_attr: torch.Tensor,
    edge_mask: torch.Tensor,
    node_mask: torch.Tensor | None = None,
) -> dict[str, torch.Tensor]:
    """Padded graph arrays with any leading shape as one batch axis (the input of
    :func:`~marl_cover.agents.models.gnn.flatten_padded`)."""
    batch = {
        "nodes": nodes.reshape(-1, *nodes.shape[-2:]),
        "edge_index": edge_index.reshape(-1, *edge_index.shape[-2:]),
        "edge_attr": edge_attr.reshape(-1, *edge_attr.shape[-2:]),
        "edge_mask": edge_mask.reshape(-1, edge_mask.shape[-1]),
    }
    if node_mask is not None:
        batch["node_mask"] = node_mask.reshape(-1, node_mask.shape[-1])
    return batch


class Tempered(nn.Module):
    """A ``(logits, mask)`` module with its logits divided by ``temperature`` (below 1: a
    sharper sampling policy with the same argmax)."""

    def __init__(self, module: nn.Module, temperature: float) -> None:
        super().__init__()
        if temperature <= 0:
            raise ValueError(f"temperature must be > 0, got {temperature}")
        self.module = module
        self.temperature = temperature

    def forward(self, *inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The wrapped module's logits divided by the temperature, and its mask."""
        logits, mask = self.module(*inputs)
        return logits / self.temperature, mask


def make_actor(
    gnn: AggregationGNN,
    observation_key: Any = "observation",
    action_key: Any = "action",
    mask_key: Any = None,
    temperature: float = 1.0,
) -> Any:
    """A TorchRL ``ProbabilisticActor`` over ``EgoGraphLogits`` with a ``MaskedCategorical``.

    Args:
        gnn: The shared network.
        observation_key: Key (or nested key, e.g. ``("robot", "observation")``) under which the
            padded ego-graph entries (:data:`GRAPH_KEYS`) live.
        action_key: Where the sampled action goes; logits, mask and log-probability are written
            beside it (``"logits"``, ``"mask"``, ``"sample_log_prob"`` under the same prefix).
        mask_key: Where the action mask is read (default: ``action_mask`` inside the
            observation; TorchRL's ``PettingZooWrapper`` lifts it to ``(group, "action_mask")``).
        temperature: Divides the logits of the sampling policy (see :class:`Tempered`).

    A network with a ``time_horizon`` also reads ``steps_left`` inside the observation.
    """
    prefix = observation_key if isinstance(observation_key, tuple) else (observation_key,)
    in_keys = [(*prefix, key) for key in GRAPH_KEYS[:-1]]
    in_keys.append(mask_key if mask_key is not None else (*prefix, "action_mask"))
    if gnn.config.time_horizon is not None:
        in_keys.append((*prefix, "steps_left"))
    return _masked_actor(EgoGraphLogits(gnn), in_keys, action_key, temperature)


def make_state_actor(
    gnn: AggregationGNN,
    num_robots: int,
    state_key: Any = "state",
    action_key: Any = ("robot", "action"),
    mask_key: Any = ("robot", "action_mask"),
    temperature: float = 1.0,
) -> Any:
    """A ``ProbabilisticActor`` of every robot at once over :class:`StateLogits` (the keys of
    :class:`marl_cover.agents.training.batched_env.BatchedCoverageEnv` by default; ``temperature``
    as in :func:`make_actor`; a network with a ``time_horizon`` also reads the state's
    ``steps_left``)."""
    prefix = state_key if isinstance(state_key, tuple) else (state_key,)
    in_keys = [(*prefix, key) for key in (*GRAPH_KEYS[:-1], "node_mask")]
    in_keys.append(mask_key)
    if gnn.config.time_horizon is not None:
        in_keys.append((*prefix, "steps_left"))
    module = StateLogits(gnn, num_robots)
    return _masked_actor(module, in_keys, action_key, temperature)


def _masked_actor(
    logits_module: nn.Module, in_keys: list[Any], action_key: Any, temperature: float = 1.0
) -> Any:
    """A ``ProbabilisticActor`` with a ``MaskedCategorical`` over a module returning
    ``(logits, mask)``; logits, mask and log-probability are written beside ``action_key``."""
    from tensordict.nn import TensorDictModule
    from torchrl.modules import MaskedCategorical, ProbabilisticActor

    def beside(name: str) -> Any:
        return (*action_key[:-1], name) if isinstance(action_key, tuple) else name

    if temperature != 1.0:
        logits_module = Tempered(logits_module, temperature)
    module = TensorDictModule(
        logits_module, in_keys=in_keys, out_keys=[beside("logits"), beside("mask")]
    )
    return ProbabilisticActor(
        module,
        in_keys={"logits": beside("logits"), "mask": beside("mask")},
        out_keys=[action_key],
        distribution_class=MaskedCategorical,
        return_log_prob=True,
        log_prob_key=beside("sample_log_prob"),
    )
