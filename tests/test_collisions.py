"""The priority-index collision resolver: table of cases and a property test."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from marl_cover.collisions import resolve_collisions, resolve_collisions_compiled
from marl_cover.ego import EgoScratch, numba_available
from marl_cover.graph import SpatialGraph

CASES = [
    # name, current, targets, allow_swaps, expected next
    ("free moves", [0, 1], [2, 3], True, [2, 3]),
    ("everyone stays", [4, 5], [4, 5], True, [4, 5]),
    ("same target, lower index wins", [0, 1], [5, 5], True, [5, 1]),
    ("same target, lower index wins whatever the order", [1, 0], [5, 5], True, [5, 0]),
    ("into a robot that stays", [1, 2], [2, 2], True, [1, 2]),
    ("chain follows a free head", [1, 2, 3], [2, 3, 4], True, [2, 3, 4]),
    ("chain behind a stopped head stays", [1, 2, 3], [2, 3, 3], True, [1, 2, 3]),
    ("chain listed head first", [3, 2, 1], [4, 3, 2], True, [4, 3, 2]),
    ("head wins a conflict, chain follows", [1, 2, 4], [2, 3, 3], True, [2, 3, 4]),
    ("head loses a conflict, chain stays", [1, 4, 2], [2, 3, 3], True, [1, 3, 2]),
    ("cycle of three moves", [1, 2, 3], [2, 3, 1], True, [2, 3, 1]),
    ("cycle of four moves without swaps", [1, 2, 3, 4], [2, 3, 4, 1], False, [2, 3, 4, 1]),
    ("swap allowed", [1, 2], [2, 1], True, [2, 1]),
    ("swap forbidden", [1, 2], [2, 1], False, [1, 2]),
    ("blocked winner keeps the loser out", [1, 4, 3], [3, 3, 3], True, [1, 4, 3]),
    ("blocked swap blocks its chain", [1, 2, 0], [2, 1, 1], False, [1, 2, 0]),
    ("no robots", [], [], True, []),
]


@pytest.mark.parametrize(
    ("current", "targets", "allow_swaps", "expected"),
    [case[1:] for case in CASES],
    ids=[case[0] for case in CASES],
)
@pytest.mark.parametrize("resolver", ["numpy", "compiled"])
def test_cases(current, targets, allow_swaps, expected, resolver) -> None:
    resolve = resolver_of(resolver)
    result = resolve(
        np.array(current, dtype=np.int64), np.array(targets, dtype=np.int64), allow_swaps
    )
    assert result.tolist() == expected


@pytest.mark.parametrize("resolver", ["numpy", "compiled"])
def test_rejects_shared_start(resolver) -> None:
    with pytest.raises(ValueError, match="share waypoint 3"):
        resolver_of(resolver)(np.array([3, 3]), np.array([1, 2]), True)


def resolver_of(name: str):  # noqa: ANN201
    """The numpy resolver, or the compiled one with fresh tables of 16 waypoints (checked to
    be left as they were found)."""
    if name == "numpy":
        return resolve_collisions
    pytest.importorskip("numba")
    scratch = EgoScratch(SpatialGraph.from_edges(np.zeros((16, 2)) + np.arange(16)[:, None], []))

    def resolve(current, targets, allow_swaps):  # noqa: ANN001, ANN202
        try:
            return resolve_collisions_compiled(current, targets, allow_swaps, scratch)
        finally:
            assert (scratch.robot_at == -1).all() and (scratch.claim == -1).all()

    return resolve


@st.composite
def scenarios(draw):  # noqa: ANN201
    num_nodes = draw(st.integers(1, 12))
    num_robots = draw(st.integers(0, num_nodes))
    current = draw(st.permutations(range(num_nodes)))[:num_robots]
    targets = draw(
        st.lists(st.integers(0, num_nodes - 1), min_size=num_robots, max_size=num_robots)
    )
    return np.array(current, dtype=np.int64), np.array(targets, dtype=np.int64), draw(st.booleans())


@settings(max_examples=400, deadline=None)
@given(scenarios())
def test_properties(scenario) -> None:
    current, targets, allow_swaps = scenario
    result = resolve_collisions(current, targets, allow_swaps)
    if numba_available():  # the compiled resolver gives the same moves
        assert resolver_of("compiled")(current, targets, allow_swaps).tolist() == result.tolist()
    # never two robots on one waypoint
    assert len(np.unique(result)) == len(result)
    # every robot either reaches its target or stays
    assert np.all((result == targets) | (result == current))
    for i in np.flatnonzero(result != targets):
        # a robot held back had a reason: its target is taken at the next step, or it swaps
        taken = np.any(np.delete(result, i) == targets[i])
        swap = np.any((current == targets[i]) & (targets == current[i]))
        assert taken or (swap and not allow_swaps)
    for i in np.flatnonzero((result == targets) & (targets != current)):
        # whoever moves to a waypoint has the lowest index among those that wanted it
        rivals = np.flatnonzero((targets == targets[i]) & (current != targets))
        assert rivals.min() == i


@pytest.mark.parametrize("allow_swaps", [True, False])
def test_compiled_resolver_agrees_on_crowds(allow_swaps: bool) -> None:
    """Thousands of robots on a few more waypoints: long chains, cycles, contested targets."""
    pytest.importorskip("numba")
    rng = np.random.default_rng(int(allow_swaps))
    scratch = EgoScratch(
        SpatialGraph.from_edges(np.zeros((3000, 2)) + np.arange(3000)[:, None], [])
    )
    for _ in range(20):
        current = rng.permutation(3000)[:2500].astype(np.int64)
        targets = np.where(
            rng.random(2500) < 0.7,
            current[rng.integers(0, 2500, 2500)],
            rng.integers(0, 3000, 2500),
        ).astype(np.int64)
        expected = resolve_collisions(current, targets, allow_swaps)
        got = resolve_collisions_compiled(current, targets, allow_swaps, scratch)
        np.testing.assert_array_equal(got, expected)
        assert (expected != current).any()
