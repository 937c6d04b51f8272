"""Mean aggregation over a flat graph, and the receptive field of a set of output edges.

The aggregation GNN's building blocks that do not depend on its weights: the mean of incoming
messages at each node (``index_add_`` with inverse degrees), the same as one sparse ``(V, V)``
operator for the linear model's diffusion, and the nodes within reach of the output edges, in
order of distance (:func:`receptive_field`), which the non-linear model limits its work to.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import torch

try:  # optional (the ``fast`` extra): the receptive field's distances, compiled
    from marl_cover.agents.models._field_numba import capped_distances as _capped_distances
except ImportError:
    _capped_distances = None  # type: ignore[assignment]


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
