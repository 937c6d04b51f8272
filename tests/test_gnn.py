"""The aggregation GNNs: ego-graph (decentralized) == state (centralized), equivariance, masks."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import marl_cover

torch = pytest.importorskip("torch")

from marl_cover.agents.models import AggregationGNN, GNNConfig  # noqa: E402
from marl_cover.agents.models.checkpoints import load_model, save_model  # noqa: E402
from marl_cover.agents.models.logits import centralized_logits, decentralized_logits  # noqa: E402


def tensors(arrays: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
    return {k: torch.as_tensor(v) for k, v in arrays.items()}


def state_graph(
    num_robots: int, hops: int, city_size: int, seed: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``nodes, edge_index, edge_attr`` (float64, padding cut) of a city's first state."""
    env = marl_cover.parallel_env(num_robots=num_robots, hops=hops, city_size=city_size)
    env.reset(seed=seed)
    state = tensors(env.state())
    keep = state["edge_mask"]
    return (
        state["nodes"].double(),
        state["edge_index"][:, keep],
        state["edge_attr"][keep].double(),
    )


def random_states(hops: int, seed: int, task: str = "coverage"):
    env = marl_cover.parallel_env(num_robots=6, hops=hops, city_size=200, task=task)
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    for _ in range(3):
        yield env
        env.step({a: int(rng.integers(5)) for a in env.agents})


@pytest.mark.parametrize("kind", ["linear", "nonlinear"])
@pytest.mark.parametrize("hops", [1, 3, 19])
def test_ego_graphs_give_the_logits_of_one_pass_over_the_state(kind: str, hops: int) -> None:
    torch.manual_seed(hops)
    model = AggregationGNN(GNNConfig(kind=kind, hops=hops)).double()
    for env in random_states(hops, seed=hops):
        batch = {
            k: v.double() if v.is_floating_point() else v
            for k, v in tensors(env.observe_batch()).items()
        }
        state = {
            k: v.double() if v.is_floating_point() else v for k, v in tensors(env.state()).items()
        }
        with torch.no_grad():
            local = decentralized_logits(model, batch)
            central = centralized_logits(model, state)
        mask = torch.as_tensor(env.state()["action_mask"]).bool()
        assert torch.equal(torch.isinf(local), ~mask) and torch.equal(torch.isinf(central), ~mask)
        torch.testing.assert_close(local[mask], central[mask], atol=1e-5, rtol=0)
        # and in float32, as trained
        with torch.no_grad():
            single = decentralized_logits(model.float(), tensors(env.observe_batch()))
        torch.testing.assert_close(single[mask].double(), central[mask], atol=1e-4, rtol=0)
        model.double()


@pytest.mark.parametrize("kind", ["linear", "nonlinear"])
def test_a_model_with_a_clock_reads_steps_left_in_both_modes(kind: str) -> None:
    torch.manual_seed(7)
    model = AggregationGNN(GNNConfig(kind=kind, hops=3, time_horizon=50)).double()
    assert model.node_encoder[0].in_features == 5
    for env in random_states(3, seed=7):
        batch = {
            k: v.double() if v.is_floating_point() else v
            for k, v in tensors(env.observe_batch()).items()
        }
        state = {
            k: v.double() if v.is_floating_point() else v for k, v in tensors(env.state()).items()
        }
        assert torch.equal(batch["steps_left"], state["steps_left"].expand(6))
        mask = torch.as_tensor(env.state()["action_mask"]).bool()
        with torch.no_grad():
            local = decentralized_logits(model, batch)
            central = centralized_logits(model, state)
            later = centralized_logits(model, {**state, "steps_left": state["steps_left"] - 5})
        torch.testing.assert_close(local[mask], central[mask], atol=1e-5, rtol=0)
        assert not torch.allclose(later[mask], central[mask])
        with pytest.raises(KeyError, match="steps_left"):
            decentralized_logits(model, {k: v for k, v in batch.items() if k != "steps_left"})
    with pytest.raises(ValueError, match="time_horizon"):
        GNNConfig(time_horizon=0)


@pytest.mark.parametrize("kind", ["linear", "nonlinear"])
def test_padded_batches_of_partial_ego_graphs_equal_one_at_a_time(kind: str) -> None:
    """Exploration: a batch of ego-graphs of the known graph (different sizes, padded) gives
    each robot the logits it gets alone and in one pass over the discovered ``state()``; no
    padding or undiscovered waypoint leaks into a real node (the paper's phantom edges)."""
    torch.manual_seed(7)
    model = AggregationGNN(GNNConfig(kind=kind, hops=5)).double()

    def double(arrays: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
        return {k: v.double() if v.is_floating_point() else v for k, v in tensors(arrays).items()}

    sizes = set()
    for env in random_states(5, seed=2, task="exploration"):
        batch = double(env.observe_batch())
        sizes.update(batch["node_mask"].sum(dim=1).tolist())
        mask = batch["action_mask"].bool()
        with torch.no_grad():
            together = decentralized_logits(model, batch)
            central = centralized_logits(model, double(env.state()))
            for i in range(len(mask)):
                alone = decentralized_logits(model, {k: v[i : i + 1] for k, v in batch.items()})
                torch.testing.assert_close(
                    alone[0][mask[i]], together[i][mask[i]], atol=1e-10, rtol=0
                )
        torch.testing.assert_close(together[mask], central[mask], atol=1e-5, rtol=0)
    assert len(sizes) > 3  # the ego-graphs really differ in size


@pytest.mark.parametrize("kind", ["linear", "nonlinear"])
def test_renumbering_nodes_and_edges_changes_nothing(kind: str) -> None:
    torch.manual_seed(0)
    model = AggregationGNN(GNNConfig(kind=kind, hops=5)).double()
    nodes, index, attr = state_graph(num_robots=4, hops=5, city_size=150, seed=4)
    with torch.no_grad():
        reference = model(nodes, index, attr)
        rng = np.random.default_rng(0)
        node_perm = torch.as_tensor(rng.permutation(nodes.shape[0]))  # new position of each node
        edge_perm = torch.as_tensor(rng.permutation(index.shape[1]))
        inverse = torch.empty_like(node_perm)
        inverse[node_perm] = torch.arange(len(node_perm))
        renumbered = model(nodes[inverse], node_perm[index][:, edge_perm], attr[edge_perm])
    torch.testing.assert_close(renumbered, reference[edge_perm], atol=1e-9, rtol=0)


def test_masked_actions_get_no_probability() -> None:
    model = AggregationGNN(GNNConfig(hops=3))
    env = marl_cover.parallel_env(num_robots=4, hops=3, city_size=120)
    env.reset(seed=1)
    batch = tensors(env.observe_batch())
    with torch.no_grad():
        probs = torch.softmax(decentralized_logits(model, batch), dim=-1)
    mask = batch["action_mask"].bool()
    assert torch.all(probs[~mask] == 0) and torch.allclose(probs.sum(-1), torch.ones(4))


def test_parameter_count_matches_the_paper_shape() -> None:
    linear = AggregationGNN(GNNConfig(kind="linear", hops=19, hidden=16))
    count = sum(p.numel() for p in linear.parameters())
    # encoders (4->16->16->16 and 1->16->16->16), edge decoder (16x3), readout (20*16 + 1)
    assert count == (4 * 16 + 16 + 2 * 272) + (16 + 16 + 2 * 272) + 3 * 272 + (20 * 16 + 1)


def test_per_hop_blocks_have_their_own_weights() -> None:
    shared = AggregationGNN(GNNConfig(hops=5, hidden=8))
    per_hop = AggregationGNN(GNNConfig(hops=5, hidden=8, per_hop=True))
    block = sum(p.numel() for p in shared.edge_block.parameters())
    node = sum(p.numel() for p in shared.node_block.parameters())
    extra = sum(p.numel() for p in per_hop.parameters()) - sum(
        p.numel() for p in shared.parameters()
    )
    assert extra == 4 * block + 3 * node  # 5 edge blocks and 4 node blocks instead of 1 + 1
    assert per_hop.blocks(0)[0] is not per_hop.blocks(1)[0] and per_hop.blocks(4)[1] is None
    with pytest.raises(ValueError, match="per_hop applies to the non-linear model only"):
        GNNConfig(kind="linear", per_hop=True)


def test_per_hop_copy_keeps_the_logits_and_frees_the_hops() -> None:
    torch.manual_seed(3)
    shared = AggregationGNN(GNNConfig(hops=4, hidden=8)).double()
    copy = shared.per_hop_copy()
    assert copy.config == GNNConfig(hops=4, hidden=8, per_hop=True)
    assert len(copy.edge_blocks) == 4 and len(copy.node_blocks) == 3
    graph = state_graph(num_robots=3, hops=4, city_size=90, seed=5)
    torch.testing.assert_close(copy(*graph), shared(*graph), atol=0, rtol=0)
    # the copies are separate tensors: a change to one hop leaves the others and the source
    with torch.no_grad():
        copy.edge_blocks[1][0].weight.add_(1.0)
    torch.testing.assert_close(copy.edge_blocks[2][0].weight, shared.edge_block[0].weight)
    assert not torch.equal(copy(*graph), shared(*graph))
    with pytest.raises(ValueError, match="non-linear shared-block model"):
        copy.per_hop_copy()
    with pytest.raises(ValueError, match="non-linear shared-block model"):
        AggregationGNN(GNNConfig(kind="linear", hops=2)).per_hop_copy()


@pytest.mark.parametrize(
    "config",
    [
        GNNConfig(kind="linear", hops=4, hidden=8),
        GNNConfig(kind="nonlinear", hops=4, hidden=8),
        GNNConfig(kind="nonlinear", hops=3, hidden=8, residual=True),
        GNNConfig(kind="nonlinear", hops=4, hidden=8, per_hop=True, time_horizon=50),
    ],
    ids=str,
)
def test_wider_copy_keeps_the_logits_and_trains_the_new_units(config) -> None:
    torch.manual_seed(4)
    narrow = AggregationGNN(config).double()
    wide = narrow.wider_copy(13)
    assert wide.config == replace(config, hidden=13)
    nodes, edge_index, edge_attr = state_graph(num_robots=3, hops=4, city_size=90, seed=5)
    if config.time_horizon is not None:
        nodes = torch.cat([nodes, torch.full_like(nodes[:, :1], 0.5)], dim=1)
    graph = (nodes, edge_index, edge_attr)
    torch.testing.assert_close(wide(*graph), narrow(*graph), atol=1e-12, rtol=0)
    torch.testing.assert_close(wide.reference_forward(*graph), narrow(*graph), atol=1e-12, rtol=0)
    # the old units read no new unit, yet those zero weights get gradients
    assert torch.all(wide.readout.weight[0].view(config.hops + 1, 13)[:, 8:] == 0)
    wide(*graph).square().sum().backward()
    assert wide.readout.weight.grad[0].view(config.hops + 1, 13)[:, 8:].abs().sum() > 0
    assert wide.edge_decoder[0].weight.grad[:8, 8:].abs().sum() > 0
    # the same seed gives the same new units
    again = narrow.wider_copy(13)
    for a, b in zip(wide.parameters(), again.parameters(), strict=True):
        assert torch.equal(a, b)
    with pytest.raises(ValueError, match="hidden > 8"):
        narrow.wider_copy(8)


@pytest.mark.parametrize(
    "config",
    [
        GNNConfig(kind="linear", hops=3, hidden=8),
        GNNConfig(kind="nonlinear", hops=3, hidden=8),
        GNNConfig(kind="nonlinear", hops=3, hidden=8, per_hop=True, norm=True),
    ],
    ids=str,
)
def test_deeper_copy_keeps_the_logits_and_trains_the_far_hops(config) -> None:
    torch.manual_seed(6)
    near = AggregationGNN(config).double()
    if config.per_hop:  # distinct blocks, so that a copy from the wrong hop would show
        with torch.no_grad():
            for p in near.parameters():
                p.add_(0.1 * torch.randn_like(p))
    deep = near.deeper_copy(6)
    assert deep.config == replace(config, hops=6)
    graph = state_graph(num_robots=3, hops=6, city_size=90, seed=5)
    torch.testing.assert_close(deep(*graph), near(*graph), atol=1e-12, rtol=0)
    torch.testing.assert_close(deep.reference_forward(*graph), near(*graph), atol=1e-12, rtol=0)
    # the new stages read nothing yet, but their readout weights get gradients
    assert torch.all(deep.readout.weight[0, 4 * 8 :] == 0)
    deep(*graph).square().sum().backward()
    assert deep.readout.weight.grad[0, 4 * 8 :].abs().sum() > 0
    if config.per_hop:  # hops 0..2 keep their blocks; the new ones copy the last
        for hop in range(3):
            assert torch.equal(deep.edge_blocks[hop][0].weight, near.edge_blocks[hop][0].weight)
        for hop in range(3, 6):
            assert torch.equal(deep.edge_blocks[hop][0].weight, near.edge_blocks[2][0].weight)
        for hop in range(2, 5):
            assert torch.equal(deep.node_blocks[hop][0].weight, near.node_blocks[1][0].weight)
            assert torch.equal(deep.node_norms[hop].weight, near.node_norms[1].weight)
    with pytest.raises(ValueError, match="hops > 3"):
        near.deeper_copy(3)


def test_grown_to_widens_and_splits_the_hops_or_says_why_not() -> None:
    torch.manual_seed(5)
    shared = AggregationGNN(GNNConfig(hops=3, hidden=8)).double()
    target = GNNConfig(hops=3, hidden=10, per_hop=True)
    grown = shared.grown_to(target)
    assert grown.config == target
    graph = state_graph(num_robots=2, hops=3, city_size=90, seed=6)
    torch.testing.assert_close(grown(*graph), shared(*graph), atol=1e-12, rtol=0)
    assert shared.grown_to(shared.config) is shared
    deeper = shared.grown_to(GNNConfig(hops=5, hidden=8, per_hop=True))
    assert len(deeper.edge_blocks) == 5 and len(deeper.node_blocks) == 4
    torch.testing.assert_close(deeper(*graph), shared(*graph), atol=1e-12, rtol=0)
    for other in (
        GNNConfig(hops=2, hidden=8),
        GNNConfig(hops=3, hidden=4),
        GNNConfig(kind="linear", hops=3, hidden=8),
    ):
        with pytest.raises(ValueError, match="cannot grow into"):
            shared.grown_to(other)


@pytest.mark.parametrize(
    "config",
    [
        GNNConfig(kind="linear", hops=1),
        GNNConfig(kind="linear", hops=7),
        GNNConfig(kind="nonlinear", hops=1),
        GNNConfig(kind="nonlinear", hops=6),
        GNNConfig(kind="nonlinear", hops=4, residual=True, hidden=8),
        GNNConfig(kind="nonlinear", hops=5, per_hop=True, hidden=8),
        GNNConfig(kind="nonlinear", hops=1, per_hop=True),
        GNNConfig(kind="nonlinear", hops=19, hidden=8),
        GNNConfig(kind="nonlinear", hops=12, per_hop=True, residual=True, hidden=4),
        GNNConfig(kind="nonlinear", hops=4, norm=True, hidden=8),
        GNNConfig(kind="nonlinear", hops=5, per_hop=True, norm=True, residual=True, hidden=8),
    ],
    ids=str,
)
def test_fast_forward_and_its_gradients_equal_the_plain_formula(config: GNNConfig) -> None:
    torch.manual_seed(config.hops)
    model = AggregationGNN(config).double()
    graph = state_graph(num_robots=3, hops=config.hops, city_size=90, seed=2)
    some_edges = torch.tensor([0, 3, 7, 11, 5, 0])
    fast = model(*graph, out_edges=some_edges)
    reference = model.reference_forward(*graph)
    torch.testing.assert_close(fast, reference[some_edges], atol=1e-10, rtol=0)
    torch.testing.assert_close(model(*graph), reference, atol=1e-10, rtol=0)
    parameters = list(model.parameters())
    fast_grads = torch.autograd.grad(fast.square().sum(), parameters, allow_unused=True)
    reference_grads = torch.autograd.grad(
        reference[some_edges].square().sum(), parameters, allow_unused=True
    )
    for parameter, fast_grad, reference_grad in zip(
        parameters, fast_grads, reference_grads, strict=True
    ):
        zero = torch.zeros_like(parameter)  # a parameter that reaches no output has no gradient
        torch.testing.assert_close(
            zero if fast_grad is None else fast_grad,
            zero if reference_grad is None else reference_grad,
            atol=1e-9,
            rtol=0,
        )


def test_the_receptive_field_of_an_output_edge_on_a_path() -> None:
    from marl_cover.agents.models.aggregation import receptive_field

    # 0 - 1 - 2 - 3 - 4 - 5, both ways; the output is edge 1 (1 -> 0)
    pairs = [(0, 1), (1, 0), (1, 2), (2, 1), (2, 3), (3, 2), (3, 4), (4, 3), (4, 5), (5, 4)]
    edge_index = torch.tensor(pairs).t()
    field = receptive_field(edge_index, torch.tensor([1]), hops=3, num_nodes=6)
    # distances 0, 0, 1, 2, 3, 3 (capped at hops): block 0 updates the nodes within 1 hop,
    # reading senders within 2; nodes 4 and 5 are never read
    assert field.node_order.tolist() == [0, 1, 2, 3]
    assert field.node_counts == [2, 3, 4, 6]
    # edges into nodes 0 and 1 (receiver distance 0), then into node 2 (distance 1)
    assert field.edge_order.tolist() == [0, 1, 3, 2, 5]
    assert field.edge_counts == [3, 5, 7, 10]
    assert field.edge_index.tolist() == [[0, 1, 2, 1, 3], [1, 0, 1, 2, 2]]
    assert field.out_positions.tolist() == [1]


@pytest.mark.parametrize("seed", range(4))
def test_compiled_and_torch_receptive_field_distances_agree(seed: int) -> None:
    pytest.importorskip("numba")
    from marl_cover.agents.models.aggregation import output_distances

    generator = torch.Generator().manual_seed(seed)
    num_nodes, num_edges = 60, 150  # directed, with repeats, self-loops and isolated nodes
    edge_index = torch.randint(0, num_nodes, (2, num_edges), generator=generator)
    for hops in (1, 2, 5, 9, 40):
        out_edges = torch.randint(0, num_edges, (7,), generator=generator)  # repeats too
        reference = output_distances(edge_index, out_edges, hops, num_nodes, compiled=False)
        compiled = output_distances(edge_index, out_edges, hops, num_nodes, compiled=True)
        assert torch.equal(reference, compiled), hops
        assert reference.max() <= hops
    # the path of the test above: distances 0, 0, 1, 2, 3, 3 (capped at 3)
    pairs = [(0, 1), (1, 0), (1, 2), (2, 1), (2, 3), (3, 2), (3, 4), (4, 3), (4, 5), (5, 4)]
    path = torch.tensor(pairs).t()
    found = output_distances(path, torch.tensor([1]), 3, 6, compiled=True)
    assert found.tolist() == [0, 0, 1, 2, 3, 3]


def test_weights_changed_in_place_reach_the_next_forward_without_gradients() -> None:
    torch.manual_seed(0)
    model = AggregationGNN(GNNConfig(hops=3, per_hop=True, hidden=8)).double()
    other = AggregationGNN(GNNConfig(hops=3, per_hop=True, hidden=8)).double()
    graph = state_graph(num_robots=2, hops=3, city_size=60, seed=1)
    edges = torch.tensor([0, 1, 2, 3, 4])
    with torch.inference_mode():
        before = model(*graph, out_edges=edges)
        model.edge_blocks[1][0].weight.add_(0.5)  # the split first layer is cached
        changed = model(*graph, out_edges=edges)
        model.load_state_dict(other.state_dict())
        loaded = model(*graph, out_edges=edges)
        model.edge_blocks[0][0].weight.data.mul_(0.5)  # .data: no version bump
        halved = model(*graph, out_edges=edges)
        model.edge_blocks[0][0].weight.data.mul_(2.0)
    with torch.no_grad():
        assert not torch.allclose(before, changed)
        model.edge_blocks[1][0].weight.sub_(0.5)
        torch.testing.assert_close(
            model(*graph, out_edges=edges), model.reference_forward(*graph)[edges]
        )
    torch.testing.assert_close(loaded, other.reference_forward(*graph)[edges])
    third = AggregationGNN(GNNConfig(hops=3, per_hop=True, hidden=8)).double()
    with torch.inference_mode():
        model.load_state_dict(third.state_dict(), assign=True)  # new tensors
        assigned = model(*graph, out_edges=edges)
    torch.testing.assert_close(assigned, third.reference_forward(*graph)[edges])
    with torch.no_grad():
        other.edge_blocks[0][0].weight.mul_(0.5)
        torch.testing.assert_close(halved, other.reference_forward(*graph)[edges])


def test_layer_norms_per_block_grow_per_hop_and_refuse_to_widen() -> None:
    torch.manual_seed(4)
    shared = AggregationGNN(GNNConfig(hops=4, hidden=8, norm=True)).double()
    with torch.no_grad():  # not the identity, so that the copy has something to keep
        for norm in (*shared.edge_norms, *shared.node_norms):
            norm.weight.uniform_(0.5, 1.5)
            norm.bias.uniform_(-0.5, 0.5)
    assert len(shared.edge_norms) == len(shared.node_norms) == 1
    copy = shared.per_hop_copy()
    assert len(copy.edge_norms) == 4 and len(copy.node_norms) == 3
    graph = state_graph(num_robots=3, hops=4, city_size=90, seed=5)
    torch.testing.assert_close(copy(*graph), shared(*graph), atol=0, rtol=0)
    with torch.no_grad():  # the norm acts: a changed gain changes the logits
        copy.node_norms[0].weight.mul_(2.0)
    assert not torch.allclose(copy(*graph), shared(*graph))
    with pytest.raises(ValueError, match="cannot keep the function"):
        shared.wider_copy(16)
    with pytest.raises(ValueError, match="norm applies to the non-linear model only"):
        GNNConfig(kind="linear", norm=True)


def test_a_stay_offset_moves_the_stay_logits_only_and_survives_growth(tmp_path) -> None:
    torch.manual_seed(8)
    plain = AggregationGNN(GNNConfig(hops=3, hidden=8)).double()
    offset = plain.grown_to(GNNConfig(hops=3, hidden=8, stay_bias=2.5))
    assert offset.config.stay_bias == 2.5 and plain.stay_logit is None
    env = next(random_states(hops=3, seed=4))
    state = {k: v.double() if v.is_floating_point() else v for k, v in tensors(env.state()).items()}
    batch = {
        k: v.double() if v.is_floating_point() else v
        for k, v in tensors(env.observe_batch()).items()
    }
    before, after = centralized_logits(plain, state), centralized_logits(offset, state)
    torch.testing.assert_close(after[:, 0], before[:, 0] + 2.5, atol=1e-12, rtol=0)
    torch.testing.assert_close(after[:, 1:], before[:, 1:], atol=0, rtol=0)  # -inf stays -inf
    torch.testing.assert_close(decentralized_logits(offset, batch), after, atol=1e-9, rtol=0)
    # the offset learns: a loss on the stays reaches it
    after[:, 0].sum().backward()
    assert offset.stay_logit is not None and offset.stay_logit.grad == float(len(after))
    with torch.no_grad():
        offset.stay_logit.fill_(-1.25)  # a learned value, which every copy keeps
    for copy in (
        offset.per_hop_copy(),
        offset.wider_copy(12),
        offset.deeper_copy(4),
    ):
        assert copy.stay_logit is not None and copy.stay_logit.item() == -1.25
    saved = tmp_path / "offset.pt"
    save_model(saved, offset, {})
    loaded, _ = load_model(saved)
    torch.testing.assert_close(
        centralized_logits(loaded.double(), state), centralized_logits(offset, state)
    )
    with pytest.raises(ValueError, match="stay offset already"):
        offset.with_stay_bias(1.0)


def test_the_diffusion_backward_equals_torch_s_own_bit_for_bit() -> None:
    from marl_cover.agents.models.aggregation import mean_operator
    from marl_cover.agents.models.gnn import _Diffusion

    generator = torch.Generator().manual_seed(0)
    num_nodes = 50  # directed edges, self-loops and isolated nodes; no repeated edge
    edge_index = torch.unique(torch.randint(0, num_nodes, (2, 400), generator=generator), dim=1)
    edge_index = edge_index[:, torch.randperm(edge_index.shape[1], generator=generator)]
    operator = mean_operator(edge_index, num_nodes, torch.float32)
    transposed = mean_operator(edge_index, num_nodes, torch.float32, transpose=True)
    assert torch.equal(transposed.to_dense(), operator.to_dense().t())
    h = torch.randn(num_nodes, 16, generator=generator, requires_grad=True)
    weights = torch.randn(num_nodes, 16, generator=generator)
    twice = _Diffusion.apply(operator, transposed, _Diffusion.apply(operator, transposed, h))
    ours = torch.autograd.grad((twice * weights).sum(), h)[0]
    plain = torch.sparse.mm(operator, torch.sparse.mm(operator, h))
    torchs = torch.autograd.grad((plain * weights).sum(), h)[0]
    assert torch.equal(twice, plain)
    assert torch.equal(ours, torchs)


@pytest.mark.parametrize(
    ("kind", "hops", "time_horizon"),
    [("nonlinear", 4, None), ("linear", 6, None), ("nonlinear", 3, 20)],
)
def test_batched_pass_on_compact_tables_equals_the_decentralized_one(
    kind: str, hops: int, time_horizon: int | None
) -> None:
    """One pass over the compact tables of a 60-robot crowd (the team outnumbers a ball) gives
    each robot the logits of its own padded ego-graph and of the state, within 1e-5."""
    from marl_cover.agents.models.logits import compact_logits
    from marl_cover.agents.models.policy import GNNPolicy

    torch.manual_seed(hops)
    model = AggregationGNN(GNNConfig(kind=kind, hops=hops, time_horizon=time_horizon)).eval()
    env = marl_cover.parallel_env(
        num_robots=60, hops=hops, city_size=400, start_density=2, observation_mode="compact"
    )
    env.reset(seed=hops)
    rng = np.random.default_rng(hops)
    policy = GNNPolicy(model)
    with torch.inference_mode():
        for _ in range(3):
            tables = env.observe_compact()
            batched = compact_logits(model, tables)
            padded = {k: torch.as_tensor(v) for k, v in env.observe_batch().items()}
            decentralized = decentralized_logits(model, padded)
            central = centralized_logits(model, tensors(env.state()))
            for other in (decentralized, central):
                assert torch.equal(torch.isinf(batched), torch.isinf(other))
                finite = torch.isfinite(other)
                torch.testing.assert_close(batched[finite], other[finite], atol=1e-5, rtol=0)
            assert np.array_equal(policy.act_compact(tables), decentralized.argmax(-1).numpy())
            env.step({a: int(rng.integers(5)) for a in env.agents})
