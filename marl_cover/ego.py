"""Graph observations: each robot's K-hop ego-subgraph, and the whole graph for ``state()``.

The observed graph has two kinds of nodes, robots and waypoints. Waypoints are linked along
the lattice; each robot is linked, in both directions, to the waypoints it can move to: its own
waypoint (the stay action) and its neighbours. A robot's ego-graph is the subgraph induced by
the nodes within ``hops`` hops of it, so a ``hops``-layer message-passing network gives the same
output at the ego robot on its ego-graph as on the whole graph. Robot nodes never shorten a
path between waypoints, so the ego-graph holds exactly the waypoints within ``hops`` lattice hops
of the robot's waypoint, and the other robots standing on them.

Padded layout of one ego-graph (``M`` nodes, ``E`` edges, the last node ``M - 1`` is a padding
*sink* that no real edge touches; padded edges run sink -> sink, so even a consumer that ignores
the masks cannot leak padding into real nodes):

- node 0: the ego robot; nodes ``1..B``: the ``B`` waypoints of the ball, in increasing map
  index; then the other robots in the ball, in robot order; then padding.
- edges ``[0, 5)``: action edge of slot ``k`` (``target -> ego``), padding where the slot has no
  waypoint; edges ``[5, 10)``: the same edges reversed; then waypoint-waypoint edges; then the
  edges of the other robots (``target -> robot``, ``robot -> target`` pairs); then padding.

The state uses the same encoding with robots ``0..R-1`` first, then every waypoint, and the
action edges of robot ``r`` at ``5 r + k`` (in) and ``5 R + 5 r + k`` (out).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from gymnasium import spaces

from marl_cover.graph import SpatialGraph

if TYPE_CHECKING:
    from marl_cover.discovery import Discovery

#: Columns of the node feature matrix.
NODE_FEATURES = ("is_robot", "is_waypoint", "is_interest", "is_frontier")
NUM_NODE_FEATURES = len(NODE_FEATURES)
#: Action slots: 0 = stay, then east, north, west, south.
NUM_ACTIONS = 5
#: The stay action's slot.
STAY = 0
#: Edges reserved at the head of an ego-graph for the ego robot's action edges, both ways.
NUM_EGO_ACTION_EDGES = 2 * NUM_ACTIONS
ROBOT_FEATURE = np.array([1.0, 0.0, 0.0, 0.0], dtype=np.float32)


def lattice_ball_size(hops: int) -> int:
    """Most lattice points within ``hops`` steps of a point of the 4-connected square lattice."""
    return 2 * hops * hops + 2 * hops + 1


@dataclass(frozen=True)
class PaddedShape:
    """Fixed padded sizes of a graph observation (``max_nodes`` includes the padding sink)."""

    max_nodes: int
    max_edges: int


def ego_shape(
    max_waypoints: int, num_robots: int, hops: int, lattice: bool, distinct: bool = True
) -> PaddedShape:
    """Padded sizes that hold any ego-graph.

    Where robots never share a waypoint (``distinct``), the other robots of an ego-graph stand
    on its ball's waypoints other than the ego robot's: at most ``ball - 1`` of them whatever
    the team's size, and the padded sizes stop growing once the team outnumbers the ball.

    Args:
        max_waypoints: Most waypoints any map of the environment can have.
        num_robots: Team size.
        hops: Radius of the ego-graph.
        lattice: Whether maps are square lattices (bounds a ball by :func:`lattice_ball_size`).
        distinct: Whether the observed robots are always on distinct waypoints.
    """
    ball = min(max_waypoints, lattice_ball_size(hops)) if lattice else max_waypoints
    others = num_robots - 1 if not distinct else min(num_robots - 1, ball - 1)
    robots = 1 + max(0, others)  # the ego robot and the others
    return PaddedShape(
        max_nodes=robots + ball + 1,
        max_edges=4 * ball + 2 * NUM_ACTIONS * robots,
    )


def state_shape(max_waypoints: int, max_waypoint_edges: int, num_robots: int) -> PaddedShape:
    """Padded sizes of the whole-graph state."""
    return PaddedShape(
        max_nodes=num_robots + max_waypoints + 1,
        max_edges=max_waypoint_edges + 2 * NUM_ACTIONS * num_robots,
    )


def graph_space(shape: PaddedShape, extra: dict[str, spaces.Space] | None = None) -> spaces.Dict:
    """The ``gymnasium`` space of a padded graph observation (see the env docstring)."""
    m, e = shape.max_nodes, shape.max_edges
    fields: dict[str, spaces.Space] = {
        "nodes": spaces.Box(0.0, 1.0, (m, NUM_NODE_FEATURES), np.float32),
        "node_pos": spaces.Box(-np.inf, np.inf, (m, 2), np.float32),
        "node_mask": spaces.Box(0, 1, (m,), np.bool_),
        "edge_index": spaces.Box(0, m - 1, (2, e), np.int64),
        "edge_attr": spaces.Box(0.0, np.inf, (e, 1), np.float32),
        "edge_mask": spaces.Box(0, 1, (e,), np.bool_),
    }
    fields.update(extra or {})
    return spaces.Dict(fields)


def waypoint_features(unvisited_interest: np.ndarray) -> np.ndarray:
    """Coverage node features of every waypoint, ``(N, 4)`` float32 (``is_frontier`` is 0)."""
    features = np.zeros((len(unvisited_interest), NUM_NODE_FEATURES), dtype=np.float32)
    features[:, 1] = 1.0
    features[:, 2] = unvisited_interest
    return features


def action_targets(graph: SpatialGraph, robot_node: np.ndarray) -> np.ndarray:
    """Waypoint reached by each action slot, ``(num_robots, 5)`` int64, ``-1`` if none."""
    return np.concatenate([robot_node[:, None], graph.neighbors[robot_node]], axis=1)


def _action_distances(graph: SpatialGraph, robot_node: np.ndarray) -> np.ndarray:
    """Edge feature of each action edge, ``(num_robots, 5)`` float32: 0 for stay."""
    zeros = np.zeros((len(robot_node), 1), dtype=np.float32)
    return np.concatenate([zeros, graph.neighbor_distances[robot_node]], axis=1)


#: Implementations of :func:`build_ego_graphs`.
EGO_BACKENDS = ("auto", "numpy", "numba")


def numba_available() -> bool:
    """Whether the compiled ego-graph kernel (optional dependency numba) can be used."""
    try:
        import marl_cover._ego_numba  # noqa: F401
    except ImportError:
        return False
    return True


def resolve_backend(backend: str) -> str:
    """``"auto"`` becomes ``"numba"`` when numba is installed, else ``"numpy"``.

    Raises:
        ValueError: an unknown backend, or ``"numba"`` without numba installed.
    """
    if backend not in EGO_BACKENDS:
        raise ValueError(f"ego backend must be one of {EGO_BACKENDS}, got {backend!r}")
    if backend == "auto":
        return "numba" if numba_available() else "numpy"
    if backend == "numba" and not numba_available():
        raise ValueError("ego backend 'numba' needs the numba package (pip install numba)")
    return backend


def build_ego_graphs(
    graph: SpatialGraph,
    robot_node: np.ndarray,
    waypoint_features: np.ndarray,
    hops: int,
    shape: PaddedShape,
    backend: str = "numpy",
    neighbors: np.ndarray | None = None,
    scratch: EgoScratch | None = None,
) -> dict[str, np.ndarray]:
    """Every robot's padded ego-graph, batched over robots.

    Both backends return identical arrays; ``"numba"`` (a compiled breadth-first search per
    robot) is faster, ``"numpy"`` (one batched ``dijkstra`` and flat scatters) needs nothing
    beyond numpy and scipy.

    Args:
        graph: The map.
        robot_node: Waypoint of each robot, ``(R,)`` int64, pairwise distinct.
        waypoint_features: ``(num_nodes, 4)`` float32 features of the waypoints, C-contiguous.
        hops: Radius of the ego-graphs.
        shape: Padded sizes (from :func:`ego_shape`).
        neighbors: The neighbour table to search, ``(N, 4)`` (default ``graph.neighbors``):
            exploration passes the known graph's (:class:`marl_cover.discovery.Discovery`),
            whose undiscovered waypoints are unreachable, so they never enter an ego-graph.
            Every robot's moves must be in it.
        scratch: The numba kernel's search state for this map (:class:`EgoScratch`), kept
            between calls by an environment; a fresh one by default.

    Returns:
        Freshly allocated arrays with a leading robot axis: ``nodes (R, M, 4)``,
        ``node_pos (R, M, 2)`` (cells, relative to the ego robot), ``node_mask (R, M)``,
        ``edge_index (R, 2, E)``, ``edge_attr (R, E, 1)``, ``edge_mask (R, E)``,
        ``action_mask (R, 5)`` int8.
    """
    if backend == "numba":
        return _build_ego_graphs_numba(
            graph, robot_node, waypoint_features, hops, shape, neighbors, scratch
        )
    if neighbors is not None:  # the known graph as a graph of its own (same waypoint ids)
        graph = SpatialGraph(graph.positions, neighbors, graph.cell_size)
    # Rows of features and positions move as single complex numbers (one 16- or 8-byte item),
    # and every scatter goes through a flat index: numpy's multi-axis fancy indexing is several
    # times slower at these sizes.
    num_robots, num_nodes = len(robot_node), graph.num_nodes
    m, e = shape.max_nodes, shape.max_edges
    sink = m - 1
    robots = np.arange(num_robots)

    in_ball = graph.hop_distances(robot_node, limit=hops) <= hops  # (R, N)
    local = np.cumsum(in_ball, axis=1).ravel()  # (R * N,); local id of a ball waypoint, 1-based
    flat = np.flatnonzero(in_ball)  # (P,) (robot, waypoint) pairs, sorted by robot
    r_idx, w_idx = np.divmod(flat, num_nodes)
    w_local = local[flat]  # (P,)
    num_ball = local[robots * num_nodes + num_nodes - 1]  # (R,)

    others = in_ball[:, robot_node]  # (R, R): robot j stands in robot i's ball
    others[robots, robots] = False
    if hops < 2:  # another robot is at least two hops away (robot -> waypoint -> robot)
        others[:] = False
    other_local = (num_ball[:, None] + np.cumsum(others, axis=1)).ravel()  # valid where others
    pair = np.flatnonzero(others)  # (Q,) (ego, other) pairs, sorted by ego robot
    oi, oj = np.divmod(pair, num_robots)
    o_local = other_local[pair]  # (Q,)
    count = 1 + num_ball + others.sum(axis=1)
    if count.max(initial=0) > sink:
        raise RuntimeError(f"an ego-graph has {count.max()} nodes, above the bound {sink}")

    # ---- nodes
    robot_row = ROBOT_FEATURE.view(np.complex128)[0]
    nodes = np.zeros((num_robots, m, NUM_NODE_FEATURES), dtype=np.float32)
    nodes_flat = nodes.view(np.complex128).reshape(-1)  # one item per node
    nodes_flat[robots * m] = robot_row
    nodes_flat[r_idx * m + w_local] = waypoint_features.view(np.complex128).reshape(-1)[w_idx]
    nodes_flat[oi * m + o_local] = robot_row
    cells = graph.complex_cells  # (N,) complex64: x + iy in cells
    node_pos = np.zeros((num_robots, m, 2), dtype=np.float32)
    pos_flat = node_pos.view(np.complex64).reshape(-1)
    robot_cells = cells[robot_node]
    pos_flat[r_idx * m + w_local] = cells[w_idx] - robot_cells[r_idx]
    pos_flat[oi * m + o_local] = robot_cells[oj] - robot_cells[oi]
    node_mask = np.arange(m)[None, :] < count[:, None]

    edge_index = np.full((num_robots, 2, e), sink, dtype=np.int64)
    index_flat = edge_index.reshape(-1)
    edge_attr = np.zeros((num_robots, e, 1), dtype=np.float32)
    attr_flat = edge_attr.reshape(-1)
    edge_mask = np.zeros((num_robots, e), dtype=bool)
    mask_flat = edge_mask.reshape(-1)

    def put_edges(robot: np.ndarray, slot: np.ndarray, send, receive, attr) -> None:  # noqa: ANN001
        index_flat[robot * (2 * e) + slot] = send
        index_flat[robot * (2 * e) + e + slot] = receive
        attr_flat[robot * e + slot] = attr
        mask_flat[robot * e + slot] = True

    # ---- the ego robot's action edges, at fixed positions (padding where a slot is empty)
    targets = action_targets(graph, robot_node)  # (R, 5)
    action_mask = targets >= 0
    target_local = np.where(action_mask, local[robots[:, None] * num_nodes + targets], sink)
    ego = np.where(action_mask, 0, sink)
    edge_index[:, 0, :NUM_ACTIONS] = target_local
    edge_index[:, 1, :NUM_ACTIONS] = ego
    edge_index[:, 0, NUM_ACTIONS:NUM_EGO_ACTION_EDGES] = ego
    edge_index[:, 1, NUM_ACTIONS:NUM_EGO_ACTION_EDGES] = target_local
    distances = _action_distances(graph, robot_node)  # (R, 5)
    edge_attr[:, :NUM_ACTIONS, 0] = distances
    edge_attr[:, NUM_ACTIONS:NUM_EGO_ACTION_EDGES, 0] = distances
    edge_mask[:, :NUM_ACTIONS] = action_mask
    edge_mask[:, NUM_ACTIONS:NUM_EGO_ACTION_EDGES] = action_mask

    # ---- waypoint-waypoint edges inside each ball
    nbr = graph.neighbors[w_idx]  # (P, 4)
    ok = nbr >= 0
    nbr_flat = (r_idx * num_nodes)[:, None] + nbr  # (P, 4)
    ok &= in_ball.reshape(-1)[np.where(ok, nbr_flat, 0)]
    hit = np.flatnonzero(ok)
    row = hit >> 2  # the (robot, waypoint) pair of each edge; 4 slots per row
    er = r_idx[row]
    num_ww = np.bincount(er, minlength=num_robots)
    slot = NUM_EGO_ACTION_EDGES + np.arange(len(er)) - (np.cumsum(num_ww) - num_ww)[er]
    put_edges(
        er,
        slot,
        w_local[row],
        local[nbr_flat.reshape(-1)[hit]],
        graph.neighbor_distances.reshape(-1)[(w_idx[row] << 2) + (hit & 3)],
    )

    # ---- the other robots' action edges that stay inside the ball, in (in, out) pairs
    other_targets = targets[oj]  # (Q, 5)
    ok = other_targets >= 0
    target_flat = (oi * num_nodes)[:, None] + other_targets
    ok &= in_ball.reshape(-1)[np.where(ok, target_flat, 0)]
    hit = np.flatnonzero(ok)
    row = hit // NUM_ACTIONS
    er = oi[row]
    num_other = np.bincount(er, minlength=num_robots)
    rank = np.arange(len(er)) - (np.cumsum(num_other) - num_other)[er]
    slot = NUM_EGO_ACTION_EDGES + num_ww[er] + 2 * rank
    target_ids = local[target_flat.reshape(-1)[hit]]
    robot_ids = o_local[row]
    pair_distances = distances[oj[row], hit % NUM_ACTIONS]
    put_edges(er, slot, target_ids, robot_ids, pair_distances)
    put_edges(er, slot + 1, robot_ids, target_ids, pair_distances)
    if num_robots and (NUM_EGO_ACTION_EDGES + num_ww + 2 * num_other).max() > e:
        raise RuntimeError("an ego-graph has more edges than its padded bound")

    return {
        "nodes": nodes,
        "node_pos": node_pos,
        "node_mask": node_mask,
        "edge_index": edge_index,
        "edge_attr": edge_attr,
        "edge_mask": edge_mask,
        "action_mask": action_mask.astype(np.int8),
    }


def row_table(graph: SpatialGraph) -> np.ndarray | None:
    """The row of each waypoint, ``(N,)`` int64, when ``graph``'s waypoints are numbered row by
    row (rows of equal ``y``, in either direction) and every edge joins the same or adjacent
    rows, as on maps built from grids; ``None`` otherwise. With it, the compiled kernels read a
    ball in index order row by row instead of sorting it."""
    y = graph.positions[:, 1]
    step = np.diff(y)
    if not (np.all(step >= 0) or np.all(step <= 0)):
        return None
    row = np.zeros(graph.num_nodes, dtype=np.int64)
    np.cumsum(step != 0, out=row[1:])
    u, slot = np.nonzero(graph.neighbors >= 0)
    if np.any(np.abs(row[graph.neighbors[u, slot]] - row[u]) > 1):
        return None
    return row


#: Sets of padded arrays a scratch keeps: one in use by the caller, one to fill.
_PADDED_POOL = 2


def unreferenced(arrays: tuple[np.ndarray, ...]) -> bool:
    """Whether only the tuple ``arrays`` refers to its arrays (no view of them is alive), so
    they can be filled again: CPython's reference counts, the tuple's reference, the loop's
    and the call's."""
    return all(sys.getrefcount(array) <= 3 for array in arrays)


class EgoScratch:
    """Search state of one map's compiled kernels, kept between calls: ``(N,)`` int32 arrays
    returned to their initial values after each call (``dist`` and ``robot_at`` are ``-1``;
    the others hold anything), and the map's :func:`row_table` (empty without one)."""

    def __init__(self, graph: SpatialGraph) -> None:
        n = graph.num_nodes
        self.num_nodes = n
        # hops from the ego waypoint while searching, then the local id; -1 outside the ball
        self.dist = np.full(n, -1, np.int32)
        self.queue = np.empty(n, np.int32)  # the search's queue
        self.ball = np.empty(n, np.int32)  # the ball in index order
        self.robot_at = np.full(n, -1, np.int32)  # robot on each waypoint, -1 if none
        self.claim = np.full(n, -1, np.int32)  # the resolver's claimer of each waypoint
        self._padded: list[tuple[tuple[int, PaddedShape], tuple[np.ndarray, ...], np.ndarray]] = []
        rows = row_table(graph)
        self.row_of = np.zeros(0, np.int32) if rows is None else rows.astype(np.int32)

    def padded_arrays(
        self, num_robots: int, shape: PaddedShape
    ) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
        """Padded arrays to fill, in their initial state, and their ``(R, 2)`` record of what
        the fill writes: a set of an earlier call that nothing refers to any more (cleared where
        it was written, :func:`marl_cover._ego_numba.clear_padded`), or a new one. Reusing a set
        spares initialising all of it and the page faults of fresh memory."""
        from marl_cover._ego_numba import clear_padded

        key = (num_robots, shape)
        for entry_key, arrays, used in self._padded:
            if entry_key == key and unreferenced(arrays):
                clear_padded(*(*arrays, used))
                return arrays, used
        arrays, used = _fresh_padded(num_robots, shape), np.zeros((num_robots, 2), np.int64)
        kept = [e for e in self._padded if not unreferenced(e[1])]  # in use: not ours to keep
        self._padded = [*kept[-(_PADDED_POOL - 1) :], (key, arrays, used)]
        return arrays, used

    def drop_padded(self, arrays: tuple[np.ndarray, ...]) -> None:
        """Forgets a set of padded arrays (one whose record of what was written is wrong)."""
        self._padded = [e for e in self._padded if e[1] is not arrays]

    def arrays(self) -> tuple[np.ndarray, ...]:
        """The kernels' scratch arguments, in their order."""
        return self.dist, self.queue, self.ball, self.robot_at, self.row_of


def _scratch_arrays(scratch: EgoScratch | None, graph: SpatialGraph) -> tuple[np.ndarray, ...]:
    """The kernels' scratch arguments, from ``scratch`` or a fresh one."""
    scratch = scratch or EgoScratch(graph)
    if scratch.num_nodes != graph.num_nodes:
        raise ValueError(
            f"the scratch was made for {scratch.num_nodes} waypoints, the map has {graph.num_nodes}"
        )
    return scratch.arrays()


#: Keys of the padded arrays, in the compiled kernels' order.
PADDED_KEYS = (
    "nodes",
    "node_pos",
    "node_mask",
    "edge_index",
    "edge_attr",
    "edge_mask",
    "action_mask",
)


def _fresh_padded(r: int, shape: PaddedShape) -> tuple[np.ndarray, ...]:
    """Padded arrays of ``r`` robots in their initial state (zeros, the sink, ``False``)."""
    m, e = shape.max_nodes, shape.max_edges
    return (
        np.zeros((r, m, NUM_NODE_FEATURES), dtype=np.float32),
        np.zeros((r, m, 2), dtype=np.float32),
        np.zeros((r, m), dtype=bool),
        np.full((r, 2, e), m - 1, dtype=np.int64),
        np.zeros((r, e, 1), dtype=np.float32),
        np.zeros((r, e), dtype=bool),
        np.zeros((r, NUM_ACTIONS), dtype=np.int8),
    )


def _build_ego_graphs_numba(
    graph: SpatialGraph,
    robot_node: np.ndarray,
    waypoint_features: np.ndarray,
    hops: int,
    shape: PaddedShape,
    neighbors: np.ndarray | None,
    scratch: EgoScratch | None,
) -> dict[str, np.ndarray]:
    from marl_cover._ego_numba import OK, TOO_MANY_NODES, fill_ego_graphs

    r, m, e = len(robot_node), shape.max_nodes, shape.max_edges
    entry = scratch.padded_arrays(r, shape) if scratch is not None else None
    arrays, used = (
        entry if entry is not None else (_fresh_padded(r, shape), np.zeros((r, 2), np.int64))
    )
    kernel_arguments: tuple[Any, ...] = (
        graph.neighbors if neighbors is None else neighbors,
        graph.neighbor_distances,
        graph.float_cells,
        np.ascontiguousarray(waypoint_features, dtype=np.float32),
        np.asarray(robot_node, dtype=np.int64),
        hops,
        *_scratch_arrays(scratch, graph),
        *arrays,
        used,
    )
    status = fill_ego_graphs(*kernel_arguments)
    if status != OK and scratch is not None:
        scratch.drop_padded(arrays)  # partly written: not reused
    if status == TOO_MANY_NODES:
        raise RuntimeError(f"an ego-graph has more nodes than its padded bound {m - 1}")
    if status != OK:
        raise RuntimeError(f"an ego-graph has more edges than its padded bound {e}")
    return dict(zip(PADDED_KEYS, arrays, strict=True))


class StateBuilder:
    """Builds the whole-graph state of one map; the waypoint part is prepared once per map."""

    def __init__(self, graph: SpatialGraph, num_robots: int, shape: PaddedShape) -> None:
        self.graph = graph
        self.num_robots = num_robots
        self.shape = shape
        m, e = shape.max_nodes, shape.max_edges
        n, r = graph.num_nodes, num_robots
        if r + n >= m or graph.num_edges + 2 * NUM_ACTIONS * r > e:
            raise ValueError(
                f"a map of {n} waypoints and {graph.num_edges} edges does not fit the state "
                f"bounds of {m - 1 - r} waypoints and {e - 2 * NUM_ACTIONS * r} edges"
            )
        sink = m - 1
        first = 2 * NUM_ACTIONS * r
        self._edge_index = np.full((2, e), sink, dtype=np.int64)
        self._edge_index[:, first : first + graph.num_edges] = graph.edge_index + r
        self._edge_attr = np.zeros((e, 1), dtype=np.float32)
        valid = graph.neighbors >= 0
        self._edge_attr[first : first + graph.num_edges, 0] = graph.neighbor_distances[valid]
        self._edge_mask = np.zeros(e, dtype=bool)
        self._edge_mask[first : first + graph.num_edges] = True
        self._node_pos = np.zeros((m, 2), dtype=np.float32)
        self._node_pos[r : r + n] = graph.positions / graph.cell_size
        self._node_mask = np.arange(m) < r + n

    def build(
        self,
        robot_node: np.ndarray,
        waypoint_features: np.ndarray,
        discovery: Discovery | None = None,
    ) -> dict[str, np.ndarray]:
        """The state for robots on ``robot_node`` ``(R,)`` and waypoint features ``(N, 4)``.

        Args:
            robot_node: Waypoint of each robot, ``(R,)``.
            waypoint_features: ``(N, 4)`` features of every waypoint.
            discovery: Exploration: only the discovered waypoints, in discovery order, and the
                known edges, in the order they became known (``None``: every waypoint, in map
                order).

        Returns:
            Fresh arrays: ``nodes (M, 4)``, ``node_pos (M, 2)`` (cells, map frame),
            ``node_mask (M,)``, ``edge_index (2, E)``, ``edge_attr (E, 1)``, ``edge_mask (E,)``,
            ``action_mask (R, 5)`` int8, ``robot_nodes (R,)`` (the node of each robot).
        """
        graph, r = self.graph, self.num_robots
        m = self.shape.max_nodes
        sink = m - 1
        nodes = np.zeros((m, NUM_NODE_FEATURES), dtype=np.float32)
        nodes[:r] = ROBOT_FEATURE
        if discovery is None:
            waypoint_id = np.arange(graph.num_nodes) + r  # (N,) node of each waypoint
            nodes[r : r + graph.num_nodes] = waypoint_features
            node_pos = self._node_pos.copy()
            node_mask = self._node_mask.copy()
            edge_index = self._edge_index.copy()
            edge_attr = self._edge_attr.copy()
            edge_mask = self._edge_mask.copy()
        else:
            waypoint_id = discovery.rank + r
            order, known = discovery.order, discovery.num_known_edges
            nodes[r : r + len(order)] = waypoint_features[order]
            node_pos = np.zeros((m, 2), dtype=np.float32)
            node_pos[r : r + len(order)] = graph.float_cells[order]
            node_mask = np.arange(m) < r + len(order)
            first = 2 * NUM_ACTIONS * r
            edge_index = np.full((2, self.shape.max_edges), sink, dtype=np.int64)
            edge_index[:, first : first + known] = discovery.edge_index + r
            edge_attr = np.zeros((self.shape.max_edges, 1), dtype=np.float32)
            edge_attr[first : first + known, 0] = discovery.edge_length
            edge_mask = np.zeros(self.shape.max_edges, dtype=bool)
            edge_mask[first : first + known] = True
        node_pos[:r] = graph.float_cells[robot_node]

        targets = action_targets(graph, robot_node)  # (R, 5)
        action_mask = targets >= 0
        target_ids = np.where(action_mask, waypoint_id[targets.clip(min=0)], sink).ravel()
        robot_ids = np.where(action_mask, np.arange(r)[:, None], sink).ravel()
        k = NUM_ACTIONS * r
        edge_index[0, :k], edge_index[1, :k] = target_ids, robot_ids
        edge_index[0, k : 2 * k], edge_index[1, k : 2 * k] = robot_ids, target_ids
        distances = _action_distances(graph, robot_node).ravel()
        edge_attr[:k, 0] = distances
        edge_attr[k : 2 * k, 0] = distances
        edge_mask[:k] = action_mask.ravel()
        edge_mask[k : 2 * k] = action_mask.ravel()
        return {
            "nodes": nodes,
            "node_pos": node_pos,
            "node_mask": node_mask,
            "edge_index": edge_index,
            "edge_attr": edge_attr,
            "edge_mask": edge_mask,
            "action_mask": action_mask.astype(np.int8),
            "robot_nodes": np.arange(r, dtype=np.int64),
        }
