"""Aggregation graph neural networks of the paper, in plain torch, shared by every robot.

Two models (``GNNConfig.kind``):

- ``"linear"`` (the paper's "identity" aggregation GNN): node and edge encoders, then ``hops``
  weightless diffusion steps (each edge takes its sender's latent, each node the mean of its
  incoming edges' latents), an edge decoder applied after every step.
- ``"nonlinear"``: the same encoder and decoder around ``hops`` applications of one shared
  graph-network block: an edge MLP on ``[e, h_receiver, h_sender]`` and a node MLP on
  ``[mean of incoming edges, h]`` (``per_hop``: a block of its own for each hop).

The decoded edge latents of every stage are concatenated and a linear readout gives one logit
per edge; a robot's action logits are those of its five action edges (target -> robot), and a
masked categorical over them is its policy. Aggregation is ``index_add_`` over a flat graph:
a batch of padded graphs is flattened with node offsets, and padded edges are dropped.

Speed (the arithmetic is tiny, so the cost is the number of torch calls and the edge-sized
work): the decoder and readout run only on the edges whose logits are asked for (a policy needs
five per robot, not one per edge), all stages in one call; the first layer of the edge MLP is
split into an edge part and two node parts computed per node before the gather (it is linear in
its inputs); the non-linear model computes only the receptive field of the outputs
(:func:`receptive_field`: block ``k`` of ``K`` updates the nodes within ``K - 2 - k`` hops of an
output edge, a prefix of the nodes sorted by that distance, about half the edge work on an
ego-graph and a fifth on 100 robots' state of the 5659-waypoint map) and runs its MLPs as
``addmm`` calls on weights split and transposed once (kept between calls without gradients);
the linear model's diffusion is one sparse ``(V, V)`` mean operator applied ``hops - 1`` times.
:meth:`AggregationGNN.reference_forward` is the plain formula on the whole graph, kept for the
tests that check the fast path and its gradients against it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple, cast

import torch
from torch import nn

from marl_cover.agents.models import growth
from marl_cover.agents.models.aggregation import (
    _Diffusion,
    mean_aggregate,
    mean_operator,
    receptive_field,
)
from marl_cover.ego import NUM_NODE_FEATURES

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
        residual: Non-linear model only: add each block's output to its input latents (off in
            the paper).
        per_hop: Non-linear model only: a block of its own for each hop instead of one block
            applied ``hops`` times (off in the paper; ``hops`` times the block parameters).
        norm: Non-linear model only: a layer normalisation (``nn.LayerNorm``) of each block's
            edge and node outputs, before any residual sum and the aggregation (off in the
            paper; one per block, so per hop with ``per_hop``).
        time_horizon: Give the network the clock: every node gets one more feature,
            ``steps_left / time_horizon`` (the actions left in the episode, which an open-loop
            expert plans for), appended by :func:`with_time_feature` from the ``steps_left`` of
            the observation or state. ``None`` (the paper): no time feature.
        stay_bias: A learned offset added to every robot's stay logit (action 0), starting at
            this value (the parameter ``stay_logit``). A cloned expert that never waits leaves
            the stay logit far below the moves, where sampling never tries it; an offset that
            changes no argmax brings stays within a sharp sampling policy's reach (see
            :meth:`AggregationGNN.grown_to`). ``None`` (the paper): no offset.
    """

    kind: str = "nonlinear"
    hops: int = 19
    hidden: int = 16
    mlp_layers: int = 3
    node_features: int = NUM_NODE_FEATURES
    edge_features: int = 1
    residual: bool = False
    per_hop: bool = False
    norm: bool = False
    time_horizon: int | None = None
    stay_bias: float | None = None

    @property
    def input_features(self) -> int:
        """Node features the encoder reads (one more with ``time_horizon``)."""
        return self.node_features + (self.time_horizon is not None)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}, got {self.kind!r}")
        if min(self.hops, self.hidden, self.mlp_layers, self.node_features, self.edge_features) < 1:
            raise ValueError(
                "hops, hidden, mlp_layers, node_features and edge_features must be >= 1, got "
                f"{self.hops}, {self.hidden}, {self.mlp_layers}, {self.node_features}, "
                f"{self.edge_features}"
            )
        if self.residual and self.kind == "linear":
            raise ValueError("residual applies to the non-linear model only")
        if self.per_hop and self.kind == "linear":
            raise ValueError("per_hop applies to the non-linear model only")
        if self.norm and self.kind == "linear":
            raise ValueError("norm applies to the non-linear model only")
        if self.time_horizon is not None and self.time_horizon < 1:
            raise ValueError(f"time_horizon must be >= 1 or None, got {self.time_horizon}")


def mlp(inputs: int, hidden: int, layers: int) -> nn.Sequential:
    """``layers`` linear layers of width ``hidden``, ReLU after all but the last."""
    modules: list[nn.Module] = []
    for i in range(layers):
        modules.append(nn.Linear(inputs if i == 0 else hidden, hidden))
        if i < layers - 1:
            modules.append(nn.ReLU())
    return nn.Sequential(*modules)


class _NodeWeights(NamedTuple):
    """A node MLP's weights as :class:`_BlockWeights` holds them: its first layer split into
    ``w_aggregate`` and ``w_self`` (transposed), its later layers as ``tail``."""

    bias: torch.Tensor
    w_aggregate: torch.Tensor
    w_self: torch.Tensor
    tail: tuple[tuple[torch.Tensor, torch.Tensor], ...]


class _BlockWeights(NamedTuple):
    """One hop's MLP weights, transposed for ``addmm``: the edge MLP's first layer split into
    its edge part ``w_edge (H, H)`` and its receiver and sender parts ``w_node_parts`` (two
    ``(H, H)``, untransposed; computed per node before the gather), the node MLP's in ``node``
    (``None`` after the last hop of a per-hop model); each MLP's later layers as
    ``(bias, weight^T)`` pairs (a ReLU before each). All are views of the parameters, so
    in-place changes to them show through."""

    edge_bias: torch.Tensor
    w_edge: torch.Tensor
    w_node_parts: tuple[torch.Tensor, torch.Tensor]
    edge_tail: tuple[tuple[torch.Tensor, torch.Tensor], ...]
    node: _NodeWeights | None


def _first_linear(layers: nn.Sequential) -> nn.Linear:
    """The first layer of an :func:`mlp`."""
    return cast(nn.Linear, layers[0])


def _tail_of(layers: nn.Sequential) -> tuple[tuple[torch.Tensor, torch.Tensor], ...]:
    """The ``(bias, weight^T)`` of an :func:`mlp`'s linear layers after the first."""
    return tuple((m.bias, m.weight.t()) for m in list(layers)[1:] if isinstance(m, nn.Linear))


def _run_tail(tail: tuple[tuple[torch.Tensor, torch.Tensor], ...], x: torch.Tensor) -> torch.Tensor:
    """Runs an :func:`mlp` from after its first linear layer (``x`` is that layer's output)."""
    for bias, weight in tail:
        x = torch.addmm(bias, torch.relu_(x), weight)
    return x


class AggregationGNN(nn.Module):
    """Edge logits of a graph of robots and waypoints (see the module docstring)."""

    def __init__(self, config: GNNConfig | None = None) -> None:
        super().__init__()
        self.config = config = config or GNNConfig()
        h, layers = config.hidden, config.mlp_layers
        self.node_encoder = mlp(config.input_features, h, layers)
        self.edge_encoder = mlp(config.edge_features, h, layers)
        self.edge_decoder = mlp(h, h, layers)
        if config.kind == "nonlinear" and config.per_hop:
            # the last hop's node update reaches no output, so it has no block
            self.edge_blocks = nn.ModuleList(mlp(3 * h, h, layers) for _ in range(config.hops))
            self.node_blocks = nn.ModuleList(mlp(2 * h, h, layers) for _ in range(config.hops - 1))
        elif config.kind == "nonlinear":
            self.edge_block = mlp(3 * h, h, layers)
            self.node_block = mlp(2 * h, h, layers)
        if config.norm:
            num_edge = config.hops if config.per_hop else 1
            num_node = config.hops - 1 if config.per_hop else 1
            self.edge_norms = nn.ModuleList(nn.LayerNorm(h) for _ in range(num_edge))
            self.node_norms = nn.ModuleList(nn.LayerNorm(h) for _ in range(num_node))
        self.readout = nn.Linear((config.hops + 1) * h, 1)
        nn.init.orthogonal_(self.readout.weight)
        nn.init.zeros_(self.readout.bias)
        self.stay_logit: nn.Parameter | None = None
        if config.stay_bias is not None:
            self.stay_logit = nn.Parameter(torch.tensor(float(config.stay_bias)))

    def _fresh(self, config: GNNConfig) -> AggregationGNN:
        """A newly initialised model of ``config`` on this model's device and dtype."""
        parameter = self.readout.weight
        return AggregationGNN(config).to(device=parameter.device, dtype=parameter.dtype)

    def per_hop_copy(self) -> AggregationGNN:
        """The same function with a block of its own for each hop (:func:`growth.per_hop_copy`)."""
        return growth.per_hop_copy(self)

    def deeper_copy(self, hops: int) -> AggregationGNN:
        """The same function with more hops (:func:`growth.deeper_copy`)."""
        return growth.deeper_copy(self, hops)

    def wider_copy(self, hidden: int, seed: int = 0) -> AggregationGNN:
        """The same function with more hidden units (:func:`growth.wider_copy`)."""
        return growth.wider_copy(self, hidden, seed)

    def with_stay_bias(self, stay_bias: float) -> AggregationGNN:
        """This model with a learned stay offset (:func:`growth.with_stay_bias`)."""
        return growth.with_stay_bias(self, stay_bias)

    def grown_to(self, config: GNNConfig, seed: int = 0) -> AggregationGNN:
        """This model grown to ``config`` with the same logits (:func:`growth.grown_to`)."""
        return growth.grown_to(self, config, seed)

    def norms(self, hop: int) -> tuple[nn.LayerNorm | None, nn.LayerNorm | None]:
        """The edge and node layer norms at ``hop`` (``None`` without ``norm``, and for the
        node after the last hop with ``per_hop``)."""
        if not self.config.norm:
            return None, None
        node_norm: nn.Module | None
        if not self.config.per_hop:
            edge_norm, node_norm = self.edge_norms[0], self.node_norms[0]
        else:
            edge_norm = self.edge_norms[hop]
            node_norm = self.node_norms[hop] if hop < self.config.hops - 1 else None
        return cast(nn.LayerNorm, edge_norm), cast(nn.LayerNorm | None, node_norm)

    def blocks(self, hop: int) -> tuple[nn.Sequential, nn.Sequential | None]:
        """The non-linear model's edge and node MLPs at ``hop`` (no node MLP after the last hop
        with ``per_hop``)."""
        if not self.config.per_hop:
            return self.edge_block, self.node_block
        node_block = self.node_blocks[hop] if hop < self.config.hops - 1 else None
        return cast(nn.Sequential, self.edge_blocks[hop]), cast(nn.Sequential | None, node_block)

    def forward(
        self,
        nodes: torch.Tensor,
        edge_index: torch.Tensor,
        edge_attr: torch.Tensor,
        out_edges: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Logits of some edges of one flat graph.

        Args:
            nodes: ``(V, node_features)`` float.
            edge_index: ``(2, E)`` long, ``[sender; receiver]``.
            edge_attr: ``(E, edge_features)`` float.
            out_edges: ``(O,)`` long ids of the edges whose logits are wanted (all by default).

        Returns:
            ``(O,)`` logits (``(E,)`` without ``out_edges``).
        """
        if out_edges is None:
            out_edges = torch.arange(edge_index.shape[1], device=edge_index.device)
        if self.config.kind == "linear":
            stages = self._linear_stages(nodes, edge_index, edge_attr, out_edges)
        else:
            stages = self._nonlinear_stages(nodes, edge_index, edge_attr, out_edges)
        return self._readout(torch.stack(stages))

    def _readout(self, stages: torch.Tensor) -> torch.Tensor:
        """Decodes ``(S, O, H)`` stage latents in one call; the readout sums over stages."""
        num_stages, num_out, hidden = stages.shape
        decoded = self.edge_decoder(stages.reshape(-1, hidden)).view(num_stages, num_out, hidden)
        weight = self.readout.weight.view(num_stages, hidden)
        return torch.einsum("soh,sh->o", decoded, weight) + self.readout.bias

    def _linear_stages(
        self,
        nodes: torch.Tensor,
        edge_index: torch.Tensor,
        edge_attr: torch.Tensor,
        out_edges: torch.Tensor,
    ) -> list[torch.Tensor]:
        # stage 0: the encoded edge; stage k >= 1: the sender's latent after k - 1 diffusions
        stages = [self.edge_encoder(edge_attr[out_edges])]
        h = self.node_encoder(nodes)
        out_senders = edge_index[0, out_edges]
        num_nodes, diffuse = nodes.shape[0], self.config.hops > 1
        operator = mean_operator(edge_index, num_nodes, h.dtype) if diffuse else None
        transposed = None
        if diffuse and torch.is_grad_enabled() and h.requires_grad:
            transposed = mean_operator(edge_index, num_nodes, h.dtype, transpose=True)
        for hop in range(self.config.hops):
            stages.append(h[out_senders])
            if hop < self.config.hops - 1:
                if transposed is None:
                    h = torch.sparse.mm(operator, h)
                else:
                    h = _Diffusion.apply(operator, transposed, h)
        return stages

    def _block_weights(self) -> list[_BlockWeights]:
        """Per hop, the weights of the edge and node MLPs as the fast path uses them (see
        :class:`_BlockWeights`). A shared block's are computed once. Without gradients they
        are kept between calls: they are views, so in-place changes show through, and they are
        made afresh when the module holds new tensors (``to()``, ``load_state_dict(assign=True)``;
        seen on the edge blocks' first layers)."""
        if torch.is_grad_enabled():
            return self._split_block_weights()
        blocks = self.edge_blocks if self.config.per_hop else [self.edge_block]
        # the blocks' current tensors
        key = [_first_linear(cast(nn.Sequential, b)).weight.data_ptr() for b in blocks]
        cached = self.__dict__.get("_weights_cache")
        if cached is None or cached[0] != key:
            cached = self.__dict__["_weights_cache"] = (key, self._split_block_weights())
        return cached[1]

    def _split_block_weights(self) -> list[_BlockWeights]:
        """:meth:`_block_weights`, computed."""
        hidden, prepared = self.config.hidden, {}
        weights = []
        for hop in range(self.config.hops):
            edge_block, node_block = self.blocks(hop)
            key = (id(edge_block), id(node_block))
            if key not in prepared:
                edge_first = _first_linear(edge_block)
                w_edge, w_receiver, w_sender = edge_first.weight.split(hidden, dim=1)
                node = None
                if node_block is not None:
                    node_first = _first_linear(node_block)
                    w_aggregate, w_self = node_first.weight.split(hidden, dim=1)
                    node = _NodeWeights(
                        node_first.bias, w_aggregate.t(), w_self.t(), _tail_of(node_block)
                    )
                prepared[key] = _BlockWeights(
                    edge_first.bias,
                    w_edge.t(),
                    (w_receiver, w_sender),
                    _tail_of(edge_block),
                    node,
                )
            weights.append(prepared[key])
        return weights

    def _nonlinear_stages(
        self,
        nodes: torch.Tensor,
        edge_index: torch.Tensor,
        edge_attr: torch.Tensor,
        out_edges: torch.Tensor,
    ) -> list[torch.Tensor]:
        hops, hidden = self.config.hops, self.config.hidden
        field = receptive_field(edge_index, out_edges, hops, nodes.shape[0])
        nodes, edge_attr = nodes[field.node_order], edge_attr[field.edge_order]
        senders, receivers = field.edge_index[0], field.edge_index[1]
        degree = torch.bincount(receivers, minlength=nodes.shape[0]).clamp(min=1)
        inverse_degree = (1.0 / degree.to(nodes.dtype)).unsqueeze(1)
        # rows 2 j and 2 j + 1 of the (2 V, H) view of h @ [W_receiver; W_sender]^T are node j's
        # receiver and sender parts; edge i reads rows receiver_rows[i] and sender_rows[i], so
        # the rows of a prefix of the edges are prefixes of both. Two gathers, not one of both
        # parts side by side: the backward of splitting that one (two zero-filled copies of it
        # an edge hop) cost 12% of a fine-tuning iteration
        receiver_rows, sender_rows = 2 * receivers, 2 * senders + 1  # (E,) each
        out = field.out_positions
        out_receiver_rows, out_sender_rows = receiver_rows[out], sender_rows[out]
        h = self.node_encoder(nodes)  # (nodes within hops - 1 of an output, H)
        e = self.edge_encoder(edge_attr)
        stages = [e[out]]
        weights = self._block_weights()
        # the receiver and sender parts side by side, (H, 2H): a copy, so made at every call
        # (the cache holds views only, which follow even in-place changes to ``.data``)
        node_pairs: dict[int, torch.Tensor] = {}
        for block in weights:
            if id(block) not in node_pairs:
                node_pairs[id(block)] = torch.cat(block.w_node_parts, dim=0).t()
        for hop in range(hops):
            block = weights[hop]
            last = hop == hops - 1
            # the last hop computes the output edges only; hop k < K - 1 the edges into the
            # nodes within K - 2 - k hops of an output (a prefix in receptive-field order)
            num_edges = out.shape[0] if last else field.edge_counts[hops - 2 - hop]
            e_in = e.index_select(0, out) if last else e[:num_edges]
            if last:
                rows = (out_receiver_rows, out_sender_rows)
            else:
                rows = (receiver_rows[:num_edges], sender_rows[:num_edges])
            pair = torch.mm(h, node_pairs[id(block)]).view(2 * h.shape[0], hidden)
            first = torch.addmm(block.edge_bias, e_in, block.w_edge)
            first += pair.index_select(0, rows[0])
            first += pair.index_select(0, rows[1])
            e_new = _run_tail(block.edge_tail, first)
            edge_norm, node_norm = self.norms(hop)
            if edge_norm is not None:
                e_new = edge_norm(e_new)
            e = e_new + e_in if self.config.residual else e_new
            if last:
                stages.append(e)
                break  # the last node update reaches no output
            stages.append(e.index_select(0, out))
            num_nodes = field.node_counts[hops - 2 - hop]
            aggregate = mean_aggregate(
                e_new, receivers[:num_edges], num_nodes, inverse_degree[:num_nodes]
            )
            node = block.node
            assert node is not None  # only the last hop has no node MLP
            first = torch.addmm(node.bias, aggregate, node.w_aggregate)
            h_self = h[:num_nodes]
            h_new = _run_tail(node.tail, first.addmm_(h_self, node.w_self))
            if node_norm is not None:
                h_new = node_norm(h_new)
            h = h_new + h_self if self.config.residual else h_new
        return stages

    def reference_forward(
        self, nodes: torch.Tensor, edge_index: torch.Tensor, edge_attr: torch.Tensor
    ) -> torch.Tensor:
        """The plain formula for every edge's logit (slow; the tests' ground truth)."""
        senders, receivers = edge_index[0], edge_index[1]
        num_nodes = nodes.shape[0]
        degree = torch.bincount(receivers, minlength=num_nodes).clamp(min=1)
        inverse_degree = (1.0 / degree.to(nodes.dtype)).unsqueeze(1)
        h = self.node_encoder(nodes)
        e = self.edge_encoder(edge_attr)
        stages = [self.edge_decoder(e)]
        for hop in range(self.config.hops):
            if self.config.kind == "linear":
                e = h[senders]
                h = mean_aggregate(e, receivers, num_nodes, inverse_degree)
            else:
                edge_block, node_block = self.blocks(hop)
                edge_norm, node_norm = self.norms(hop)
                e_new = edge_block(torch.cat([e, h[receivers], h[senders]], dim=1))
                e_new = edge_norm(e_new) if edge_norm is not None else e_new
                e = e_new + e if self.config.residual else e_new
                if node_block is not None:
                    aggregate = mean_aggregate(e_new, receivers, num_nodes, inverse_degree)
                    h_new = node_block(torch.cat([aggregate, h], 1))
                    h_new = node_norm(h_new) if node_norm is not None else h_new
                    h = h_new + h if self.config.residual else h_new
            stages.append(self.edge_decoder(e))
        return self.readout(torch.cat(stages, dim=1)).squeeze(1)
