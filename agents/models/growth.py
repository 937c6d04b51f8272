"""Growing a trained aggregation GNN into a larger one with the same logits.

Fine-tuning often starts from a model of another shape: a block of its own for each hop, more
hops, more width, a learned stay offset. Each copy below computes the same function as the
model it grows from at the start (tested), so that training continues from the policy it had.
:class:`~marl_cover.agents.models.gnn.AggregationGNN` has each as a method of the same name.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import torch
from torch import nn

if TYPE_CHECKING:
    from marl_cover.agents.models.gnn import AggregationGNN, GNNConfig


def per_hop_copy(model: AggregationGNN) -> AggregationGNN:
    """The same function as a model with a block of its own for each hop.

    Every hop's edge and node MLP starts as a copy of this model's shared block (the last
    hop has no node MLP), so the copy's logits equal this model's; training can then let
    the hops differ. A way to grow a trained shared-block model without starting over.

    Raises:
        ValueError: this is not a non-linear model with a shared block.
    """
    if model.config.kind != "nonlinear" or model.config.per_hop:
        raise ValueError(f"per_hop_copy needs a non-linear shared-block model, got {model.config}")
    copy = model._fresh(replace(model.config, per_hop=True))
    # encoders, decoder and readout by name (the shared blocks have no namesake there)
    copy.load_state_dict(model.state_dict(), strict=False)
    for block in copy.edge_blocks:
        block.load_state_dict(model.edge_block.state_dict())
    for block in copy.node_blocks:
        block.load_state_dict(model.node_block.state_dict())
    if model.config.norm:
        for norm in copy.edge_norms:
            norm.load_state_dict(model.edge_norms[0].state_dict())
        for norm in copy.node_norms:
            norm.load_state_dict(model.node_norms[0].state_dict())
    return copy.train(model.training)


def deeper_copy(model: AggregationGNN, hops: int) -> AggregationGNN:
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
    old_hops, hidden = model.config.hops, model.config.hidden
    if hops <= old_hops:
        raise ValueError(f"deeper_copy needs hops > {old_hops}, got {hops}")
    copy = model._fresh(replace(model.config, hops=hops))
    state = {k: v for k, v in model.state_dict().items() if not k.startswith("readout.")}
    copy.load_state_dict(state, strict=False)
    with torch.no_grad():
        copy.readout.weight.zero_()
        copy.readout.weight[:, : (old_hops + 1) * hidden] = model.readout.weight
        copy.readout.bias.copy_(model.readout.bias)
    if model.config.kind == "nonlinear" and model.config.per_hop:
        # (new modules, old modules, first new hop): the new hops copy the last old one
        grown = [(copy.edge_blocks, model.edge_blocks, old_hops)]
        grown.append((copy.node_blocks, model.node_blocks, old_hops - 1))
        if model.config.norm:
            grown.append((copy.edge_norms, model.edge_norms, old_hops))
            grown.append((copy.node_norms, model.node_norms, old_hops - 1))
        for new, old, first in grown:
            for module in list(new)[first:] if len(old) else []:  # a 1-hop model: no node
                module.load_state_dict(old[-1].state_dict())
    return copy.train(model.training)


def wider_copy(model: AggregationGNN, hidden: int, seed: int = 0) -> AggregationGNN:
    """The same function as a model with ``hidden`` units in every MLP and latent.

    The new units get a fresh initialisation (from ``seed``) and every weight from a new
    unit into an old one is zero, so the old units compute what they did and the logits are
    unchanged; the zero weights get gradients (the new units are active), so training can
    put the new width to use. A way to grow a trained model without starting over.

    Raises:
        ValueError: ``hidden`` is not larger than this model's width.
    """
    old_width = model.config.hidden
    if hidden <= old_width:
        raise ValueError(f"wider_copy needs hidden > {old_width}, got {hidden}")
    if model.config.norm:
        raise ValueError("wider_copy cannot keep the function of a model with norm")
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        copy = model._fresh(replace(model.config, hidden=hidden))
    old_layers = dict(model.named_modules())
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
        if model.stay_logit is not None and copy.stay_logit is not None:
            copy.stay_logit.copy_(model.stay_logit)
    return copy.train(model.training)


def with_stay_bias(model: AggregationGNN, stay_bias: float) -> AggregationGNN:
    """This model with a learned stay offset (``GNNConfig.stay_bias``) starting at
    ``stay_bias``: every stay logit moves by that much, nothing else changes.

    Raises:
        ValueError: the model has an offset already.
    """
    if model.stay_logit is not None:
        raise ValueError(f"the model has a stay offset already ({model.config.stay_bias})")
    copy = model._fresh(replace(model.config, stay_bias=float(stay_bias)))
    copy.load_state_dict(model.state_dict(), strict=False)  # all but the new offset
    return copy.train(model.training)


def grown_to(model: AggregationGNN, config: GNNConfig, seed: int = 0) -> AggregationGNN:
    """This model grown to ``config`` with the same logits: a block per hop
    (:func:`per_hop_copy`), more hops (:func:`deeper_copy`) and more width
    (:func:`wider_copy`) as ``config`` asks; itself when ``config`` is its own. A
    ``stay_bias`` that this model lacks adds a learned stay offset
    (:func:`with_stay_bias`), the one change of logits: the stays move by that much.

    Raises:
        ValueError: ``config`` differs in anything else, or asks for less.
    """
    grown = model
    if config.stay_bias is not None and model.config.stay_bias is None:
        grown = with_stay_bias(grown, config.stay_bias)
    if config.per_hop and not model.config.per_hop and model.config.kind == "nonlinear":
        grown = per_hop_copy(grown)
    if config.hops > model.config.hops:
        grown = deeper_copy(grown, config.hops)
    if config.hidden > model.config.hidden:
        grown = wider_copy(grown, config.hidden, seed=seed)
    if grown.config != config:
        raise ValueError(f"a {model.config} cannot grow into a {config}")
    return grown


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
