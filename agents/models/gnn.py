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

import warnings
from dataclasses import dataclass, replace
from typing import NamedTuple, cast

import torch
from torch import nn

from marl_cover.ego import NUM_ACTIONS, NUM_NODE_FEATURES, STAY

try:  # optional (the ``fast`` extra): the receptive field's distances, compiled
    from agents.models._field_numba import capped_distances as _capped_distances
except ImportError:
    _capped_distances = None  # type: ignore[assignment]

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


def mean_aggregate(
    messages: torch.Tensor, receivers: torch.Tensor, num_nodes: int, inverse_degree: torch.Tensor
) -> torch.Tensor:
    """Mean of ``messages (E, H)`` at each receiver, ``(num_nodes, H)`` (0 without edges)."""
    total = messages.new_zeros(num_nodes, messages.shape[1]).index_add_(0, receivers, messages)
    return total * inverse_degree


def mean_operator(
    edge_index: torch.Tensor, num_nodes: int, dtype: torch.dtype, transpose: bool = False
) -> torch.Tensor:
    """Sparse ``(V, V)`` matrix ``A`` with ``(A h)_i`` = mean of ``h_j`` over edges ``j -> i``,
    in compressed-row (CSR) form: its products cost a fifth of a coordinate-format one's here.

    ``transpose=True`` gives ``A^T`` instead, its columns sorted within each row as torch's own
    conversion of ``A.t()`` sorts them, so that products with it equal that conversion's bit for
    bit (what the backward of :class:`_Diffusion` multiplies by).
    """
    senders, receivers = edge_index[0], edge_index[1]
    degree = torch.bincount(receivers, minlength=num_nodes)
    if transpose:  # rows: senders; columns: receivers, ascending within a row
        order = torch.argsort(senders * num_nodes + receivers, stable=True)
        column_of, row_counts = receivers, torch.bincount(senders, minlength=num_nodes)
    else:
        order = torch.argsort(receivers, stable=True)
        column_of, row_counts = senders, degree
    # int32 indices: the CPU kernel (MKL) would otherwise convert them at every product
    rows = torch.zeros(num_nodes + 1, dtype=torch.int32, device=edge_index.device)
    torch.cumsum(row_counts, 0, out=rows[1:])
    columns = column_of[order].to(torch.int32)
    values = (1.0 / degree.clamp(min=1).to(dtype))[receivers[order]]
    with warnings.catch_warnings():  # CSR is "beta" in torch; this use is plain and tested
        warnings.simplefilter("ignore", UserWarning)
        return torch.sparse_csr_tensor(
            rows, columns, values, (num_nodes, num_nodes), check_invariants=False
        )


class _Diffusion(torch.autograd.Function):
    """``A @ h`` for the CSR mean operator ``A`` whose transpose ``A^T`` is given: the backward
    multiplies by ``A^T`` built once per forward pass, where ``torch.sparse.mm``'s own backward
    converts ``A.t()`` to CSR at every hop (45 ms a hop on a batch of 1000 states of the paper's
    windows, 10% of a fine-tuning iteration). The gradients are the same, bit for bit."""

    @staticmethod
    def forward(
        ctx: torch.autograd.function.FunctionCtx,
        operator: torch.Tensor,
        transposed: torch.Tensor,
        h: torch.Tensor,
    ) -> torch.Tensor:
        ctx.transposed = transposed  # type: ignore[attr-defined]
        return torch.sparse.mm(operator, h)

    @staticmethod
    def backward(
        ctx: torch.autograd.function.FunctionCtx, grad: torch.Tensor
    ) -> tuple[None, None, torch.Tensor]:
        return None, None, torch.sparse.mm(ctx.transposed, grad)  # type: ignore[attr-defined]


@dataclass(frozen=True)
class ReceptiveField:
    """The part of a flat graph that a ``hops``-block network's output edges depend on, in
    receptive-field order (see :func:`receptive_field`).

    Attributes:
        node_order: ``(V',)`` ids of the kept nodes, by hop distance to an output edge.
        edge_order: ``(E',)`` ids of the kept edges, by their receiver's distance.
        edge_index: ``(2, E')`` the kept edges between the kept nodes' new ids.
        out_positions: ``(O,)`` position of each output edge among the kept edges.
        node_counts: ``node_counts[d]``: kept nodes within ``d`` hops of an output edge.
        edge_counts: ``edge_counts[d]``: kept edges whose receiver is within ``d`` hops.
    """

    node_order: torch.Tensor
    edge_order: torch.Tensor
    edge_index: torch.Tensor
    out_positions: torch.Tensor
    node_counts: list[int]
    edge_counts: list[int]


def output_distances(
    edge_index: torch.Tensor,
    out_edges: torch.Tensor,
    hops: int,
    num_nodes: int,
    compiled: bool | None = None,
) -> torch.Tensor:
    """Each node's hop count along the edges to an endpoint of an output edge, capped at
    ``hops`` (more than ``hops - 1``, or never), ``(num_nodes,)`` long.

    Args:
        edge_index: ``(2, E)`` long, ``[sender; receiver]``.
        out_edges: ``(O,)`` long ids of the output edges.
        hops: The cap.
        num_nodes: Nodes of the graph.
        compiled: A breadth-first search by the numba kernel (CPU tensors only) or the
            reference's ``hops - 1`` Bellman-Ford rounds in torch; both give the same numbers.
            ``None``: the kernel where it can run (numba installed, tensors on the CPU).
    """
    senders, receivers = edge_index[0], edge_index[1]
    if compiled is None:
        compiled = _capped_distances is not None and edge_index.device.type == "cpu"
    elif compiled and (_capped_distances is None or edge_index.device.type != "cpu"):
        raise ValueError("compiled distances need numba installed and CPU tensors")
    if compiled:
        sources = torch.cat([senders[out_edges], receivers[out_edges]])
        found = _capped_distances(
            senders.contiguous().numpy(),
            receivers.contiguous().numpy(),
            sources.numpy(),
            num_nodes,
            hops,
        )
        return torch.from_numpy(found)
    distance = torch.full((num_nodes,), hops, dtype=torch.long, device=edge_index.device)
    distance[senders[out_edges]] = 0
    distance[receivers[out_edges]] = 0
    for _ in range(hops - 1):  # Bellman-Ford rounds toward the outputs, up to hops - 1
        reach = distance.index_select(0, receivers) + 1
        distance = distance.scatter_reduce(0, senders, reach, "amin")
    return distance


def receptive_field(
    edge_index: torch.Tensor, out_edges: torch.Tensor, hops: int, num_nodes: int
) -> ReceptiveField:
    """Which nodes and edges ``hops`` message-passing blocks need for the ``out_edges``.

    A node's distance is its hop count along the edges to an endpoint of an output edge. The
    output edges read their endpoints' latents after block ``K - 1``; a node's latent after
    block ``k`` is read by the next block only when the node lies within ``K - 1 - k`` hops;
    so block ``k < K - 1`` needs the edges into the nodes within ``K - 2 - k`` hops (the node
    update of those nodes, whose senders lie within ``K - 1 - k``) and block ``K - 1`` the
    output edges alone. Sorting nodes by distance and edges by their receiver's makes each
    block's work a prefix of the arrays; the rest of the graph is never computed, and the
    outputs are those of the whole graph. On an ego-graph of the paper's windows at K = 19
    about half the edge work remains; on a state of 100 robots on the 5659-waypoint map, a
    fifth.

    Args:
        edge_index: ``(2, E)`` long, ``[sender; receiver]``.
        out_edges: ``(O,)`` long ids of the output edges.
        hops: Blocks of the network (its receptive field).
        num_nodes: Nodes of the graph.
    """
    receivers = edge_index[1]
    # distances are capped at hops: such nodes are never needed
    distance = output_distances(edge_index, out_edges, hops, num_nodes)
    node_order = torch.argsort(distance, stable=True)
    node_counts = torch.bincount(distance, minlength=hops + 1).cumsum(0).tolist()
    node_order = node_order[: node_counts[hops - 1]]
    new_id = torch.empty_like(distance)
    new_id[node_order] = torch.arange(node_order.shape[0], device=distance.device)
    edge_distance = distance[receivers]
    edge_counts = torch.bincount(edge_distance, minlength=hops + 1).cumsum(0).tolist()
    edge_order = torch.argsort(edge_distance, stable=True)[: edge_counts[max(hops - 2, 0)]]
    position = torch.full_like(receivers, -1)
    position[edge_order] = torch.arange(edge_order.shape[0], device=distance.device)
    return ReceptiveField(
        node_order=node_order,
        edge_order=edge_order,
        edge_index=new_id[edge_index[:, edge_order]],
        out_positions=position[out_edges],
        node_counts=node_counts,
        edge_counts=edge_counts,
    )


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
        """The same function as a model with a block of its own for each hop.

        Every hop's edge and node MLP starts as a copy of this model's shared block (the last
        hop has no node MLP), so the copy's logits equal this model's; training can then let
        the hops differ. A way to grow a trained shared-block model without starting over.

        Raises:
            ValueError: this is not a non-linear model with a shared block.
        """
        if self.config.kind != "nonlinear" or self.config.per_hop:
            raise ValueError(
                f"per_hop_copy needs a non-linear shared-block model, got {self.config}"
            )
        copy = self._fresh(replace(self.config, per_hop=True))
        # encoders, decoder and readout by name (the shared blocks have no namesake there)
        copy.load_state_dict(self.state_dict(), strict=False)
        for block in copy.edge_blocks:
            block.load_state_dict(self.edge_block.state_dict())
        for block in copy.node_blocks:
            block.load_state_dict(self.node_block.state_dict())
        if self.config.norm:
            for norm in copy.edge_norms:
                norm.load_state_dict(self.edge_norms[0].state_dict())
            for norm in copy.node_norms:
                norm.load_state_dict(self.node_norms[0].state_dict())
        return copy.train(self.training)

    def deeper_copy(self, hops: int) -> AggregationGNN:
        """The same function as a model with a larger receptive field, ``hops`` blocks.

        The readout's weights of the new stages (after blocks ``K + 1 .. hops``) are zero, so
        the logits are unchanged; they get gradients, so training can put the far hops to use.
        A per-hop model's new blocks start as copies of its last ones (the last edge block, and
        the last node block for the node updates that now reach an output). A way to widen a
        trained model's view (its ego-graphs must then be ``hops`` hops too) without starting
        over.

        Raises:
            ValueError: ``hops`` is not larger than this model's.
        """
        old_hops, hidden = self.config.hops, self.config.hidden
        if hops <= old_hops:
            raise ValueError(f"deeper_copy needs hops > {old_hops}, got {hops}")
        copy = self._fresh(replace(self.config, hops=hops))
        state = {k: v for k, v in self.state_dict().items() if not k.startswith("readout.")}
        copy.load_state_dict(state, strict=False)
        with torch.no_grad():
            copy.readout.weight.zero_()
            copy.readout.weight[:, : (old_hops + 1) * hidden] = self.readout.weight
            copy.readout.bias.copy_(self.readout.bias)
        if self.config.kind == "nonlinear" and self.config.per_hop:
            # (new modules, old modules, first new hop): the new hops copy the last old one
            grown = [(copy.edge_blocks, self.edge_blocks, old_hops)]
            grown.append((copy.node_blocks, self.node_blocks, old_hops - 1))
            if self.config.norm:
                grown.append((copy.edge_norms, self.edge_norms, old_hops))
                grown.append((copy.node_norms, self.node_norms, old_hops - 1))
            for new, old, first in grown:
                for module in list(new)[first:] if len(old) else []:  # a 1-hop model: no node
                    module.load_state_dict(old[-1].state_dict())
        return copy.train(self.training)

    def wider_copy(self, hidden: int, seed: int = 0) -> AggregationGNN:
        """The same function as a model with ``hidden`` units in every MLP and latent.

        The new units get a fresh initialisation (from ``seed``) and every weight from a new
        unit into an old one is zero, so the old units compute what they did and the logits are
        unchanged; the zero weights get gradients (the new units are active), so training can
        put the new width to use. A way to grow a trained model without starting over.

        Raises:
            ValueError: ``hidden`` is not larger than this model's width.
        """
        old_width = self.config.hidden
        if hidden <= old_width:
            raise ValueError(f"wider_copy needs hidden > {old_width}, got {hidden}")
        if self.config.norm:
            raise ValueError("wider_copy cannot keep the function of a model with norm")
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            copy = self._fresh(replace(self.config, hidden=hidden))
        old_layers = dict(self.named_modules())
        with torch.no_grad():
            for name, layer in copy.named_modules():
                if not isinstance(layer, nn.Linear):
                    continue
                old = old_layers[name]
                rows = _widened_indices(old.out_features, layer.out_features, old_width)
                columns = _widened_indices(old.in_features, layer.in_features, old_width)
                # old units read old units only; new units read everything
                layer.weight[rows] = 0.0
                layer.weight[rows.unsqueeze(1), columns] = old.weight
                layer.bias[rows] = old.bias
            if self.stay_logit is not None and copy.stay_logit is not None:
                copy.stay_logit.copy_(self.stay_logit)
        return copy.train(self.training)

    def with_stay_bias(self, stay_bias: float) -> AggregationGNN:
        """This model with a learned stay offset (``GNNConfig.stay_bias``) starting at
        ``stay_bias``: every stay logit moves by that much, nothing else changes.

        Raises:
            ValueError: the model has an offset already.
        """
        if self.stay_logit is not None:
            raise ValueError(f"the model has a stay offset already ({self.config.stay_bias})")
        copy = self._fresh(replace(self.config, stay_bias=float(stay_bias)))
        copy.load_state_dict(self.state_dict(), strict=False)  # all but the new offset
        return copy.train(self.training)

    @staticmethod
    def merged(models: list[AggregationGNN]) -> AggregationGNN:
        """One network whose logits are the mean of ``models``' logits (an ensemble in one).

        The members sit side by side in a model ``len(models)`` times as wide: every MLP's
        weights are block-diagonal (member ``m`` reads and writes only its own units within
        each latent), the encoders share the raw features, and the readout averages the
        members' logits. Its argmax action is the ensemble's of
        :class:`~agents.models.policy.EnsemblePolicy` (a mean of log-softmaxes differs from
        the mean of logits by a constant per robot); one forward pass, no per-member calls.

        Raises:
            ValueError: no member, members of different configs, or a member with ``norm``
                (a layer norm across the merged width would mix the members).
        """
        if not models:
            raise ValueError("merging needs at least one model")
        config = models[0].config
        for index, model in enumerate(models):
            if model.config != config:
                raise ValueError(f"member {index} is a {model.config}, member 0 a {config}")
        if config.norm:
            raise ValueError("cannot merge models with norm (a layer norm would mix members)")
        num, width = len(models), config.hidden
        with torch.random.fork_rng(devices=[]):  # every weight is set below: no global draw
            merged = models[0]._fresh(replace(config, hidden=num * width))
        members = [dict(model.named_modules()) for model in models]
        with torch.no_grad():
            for name, layer in merged.named_modules():
                if not isinstance(layer, nn.Linear):
                    continue
                layer.weight.zero_()
                layer.bias.zero_()
                # the readout keeps its one logit: each member adds its share of the mean
                share = num if layer.out_features == members[0][name].out_features else 1
                for m, modules in enumerate(members):
                    old = modules[name]
                    rows = _member_indices(old.out_features, layer.out_features, width, m)
                    columns = _member_indices(old.in_features, layer.in_features, width, m)
                    layer.weight[rows.unsqueeze(1), columns] += old.weight / share
                    layer.bias[rows] += old.bias / share
            if merged.stay_logit is not None:  # the mean of logits: the mean of the offsets
                offsets = [cast(torch.Tensor, model.stay_logit) for model in models]
                merged.stay_logit.copy_(torch.stack(offsets).mean())
        return merged.train(models[0].training)

    def grown_to(self, config: GNNConfig, seed: int = 0) -> AggregationGNN:
        """This model grown to ``config`` with the same logits: a block per hop
        (:meth:`per_hop_copy`), more hops (:meth:`deeper_copy`) and more width
        (:meth:`wider_copy`) as ``config`` asks; itself when ``config`` is its own. A
        ``stay_bias`` that this model lacks adds a learned stay offset
        (:meth:`with_stay_bias`), the one change of logits: the stays move by that much.

        Raises:
            ValueError: ``config`` differs in anything else, or asks for less.
        """
        grown = self
        if config.stay_bias is not None and self.config.stay_bias is None:
            grown = grown.with_stay_bias(config.stay_bias)
        if config.per_hop and not self.config.per_hop and self.config.kind == "nonlinear":
            grown = grown.per_hop_copy()
        if config.hops > self.config.hops:
            grown = grown.deeper_copy(config.hops)
        if config.hidden > self.config.hidden:
            grown = grown.wider_copy(config.hidden, seed=seed)
        if grown.config != config:
            raise ValueError(f"a {self.config} cannot grow into a {config}")
        return grown

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


def _widened_indices(size: int, new_size: int, old_width: int) -> torch.Tensor:
    """Where the ``size`` entries of one side of a linear layer go in its widened copy
    (``new_size`` entries): a side that kept its size (raw features, the readout's logit) maps
    to itself; a concatenation of latents ``old_width`` wide keeps each latent's entries at the
    start of its widened segment."""
    index = torch.arange(size)
    if new_size == size:
        return index
    width = new_size // (size // old_width)
    return index // old_width * width + index % old_width


def _member_indices(size: int, new_size: int, width: int, member: int) -> torch.Tensor:
    """Where member ``member``'s ``size`` entries of one side of a linear layer go in a merge of
    members ``width`` wide (``new_size`` entries): a side that kept its size (raw features, the
    readout's logit) is shared; a concatenation of latents puts the member's units at its offset
    within each widened segment."""
    index = _widened_indices(size, new_size, width)
    return index if new_size == size else index + member * width


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
