"""Compact observations: every robot's ego-graph without padding, in step-wide tables.

The padded observation (:mod:`marl_cover.ego`) reserves room for the largest possible ego-graph,
which at K = 19 is several times the graph a robot actually sees. With
``observation_mode="compact"`` the environment writes the same ego-graphs one after the other
into a few step-wide tables (CSR layout, :class:`CompactObservations`), and each agent's
observation is a set of views into them: nothing is padded and nothing is copied per agent.

One agent's compact observation (space: :func:`compact_space`):

=================  ==============================  ===============================================
key                type                            meaning
=================  ==============================  ===============================================
``graph``          ``gymnasium.spaces.GraphInstance``  its ego-graph:
                                                   ``nodes (n, 6)`` float32, the four node features
                                                   of the padded mode and the two columns of its
                                                   ``node_pos`` (``COMPACT_NODE_COLUMNS``);
                                                   ``edges (e, 1)`` float32, the edge lengths;
                                                   ``edge_links (e, 2)`` int32, ``[sender,
                                                   receiver]`` local node ids
``action_mask``    ``(5,)`` int8                   as in the padded mode
``steps_left``     ``()`` int64                    as in the padded mode
=================  ==============================  ===============================================

Order: the nodes and edges are the padded mode's real ones, in the same order, without the
padding: node 0 is the ego robot, then the ball's waypoints by map index, then the other robots
in robot order. The edges start with the ego robot's ``A`` action edges (``A`` = the number of
available actions): its ``A`` in-edges (target -> robot) in slot order, then its ``A``
out-edges in slot order; then the waypoint edges and the other robots' edge pairs. The padded
mode holds the same edges with the empty action slots padded, so the two convert both ways
without loss (:meth:`CompactObservations.to_padded`, :func:`padded_to_compact`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from gymnasium import spaces
from gymnasium.spaces import GraphInstance

from marl_cover.ego import (
    NODE_FEATURES,
    NUM_ACTIONS,
    NUM_EGO_ACTION_EDGES,
    NUM_NODE_FEATURES,
    PADDED_KEYS,
    EgoScratch,
    PaddedShape,
    build_ego_graphs,
    unreferenced,
)
from marl_cover.graph import SpatialGraph

#: Columns of a compact node table: the node features, then the position (cells, ego frame).
COMPACT_NODE_COLUMNS = (*NODE_FEATURES, "x", "y")
#: Observation modes of the environment.
OBSERVATION_MODES = ("padded", "compact")


def compact_space(max_steps: int) -> spaces.Dict:
    """The space of one agent's compact observation (see the module docstring)."""
    low = np.array([0.0] * NUM_NODE_FEATURES + [-np.inf, -np.inf], dtype=np.float32)
    high = np.array([1.0] * NUM_NODE_FEATURES + [np.inf, np.inf], dtype=np.float32)
    return spaces.Dict(
        {
            "graph": spaces.Graph(
                node_space=spaces.Box(low, high, (len(COMPACT_NODE_COLUMNS),), np.float32),
                edge_space=spaces.Box(0.0, np.inf, (1,), np.float32),
            ),
            "action_mask": spaces.Box(0, 1, (NUM_ACTIONS,), np.int8),
            "steps_left": spaces.Box(0, max_steps, (), np.int64),
        }
    )


@dataclasses.dataclass(frozen=True)
class CompactObservations:
    """Every robot's ego-graph of one step, unpadded, in CSR tables.

    Robot ``i``'s nodes are rows ``node_offsets[i]:node_offsets[i + 1]`` of ``nodes`` and its
    edges rows ``edge_offsets[i]:edge_offsets[i + 1]`` of ``edge_links`` and ``edge_attr``,
    with node ids local to its ego-graph (the order of the module docstring).

    Attributes:
        node_offsets: ``(R + 1,)`` int64.
        nodes: ``(V, 6)`` float32, columns ``COMPACT_NODE_COLUMNS``.
        edge_offsets: ``(R + 1,)`` int64.
        edge_links: ``(E, 2)`` int32, ``[sender, receiver]`` local node ids.
        edge_attr: ``(E, 1)`` float32, edge lengths in cells.
        action_mask: ``(R, 5)`` int8.
        steps_left: ``(R,)`` int64.
    """

    node_offsets: np.ndarray
    nodes: np.ndarray
    edge_offsets: np.ndarray
    edge_links: np.ndarray
    edge_attr: np.ndarray
    action_mask: np.ndarray
    steps_left: np.ndarray

    @property
    def num_robots(self) -> int:
        """Robots (ego-graphs) in the tables."""
        return len(self.node_offsets) - 1

    @property
    def nbytes(self) -> int:
        """Bytes of the tables."""
        return sum(getattr(self, f.name).nbytes for f in dataclasses.fields(self))

    def observation(self, robot: int) -> dict[str, object]:
        """Robot ``robot``'s observation: views into the tables (see the module docstring)."""
        a, b = self.node_offsets[robot], self.node_offsets[robot + 1]
        c, d = self.edge_offsets[robot], self.edge_offsets[robot + 1]
        return {
            "graph": GraphInstance(self.nodes[a:b], self.edge_attr[c:d], self.edge_links[c:d]),
            "action_mask": self.action_mask[robot],
            "steps_left": self.steps_left[robot, ...],
        }

    def observations(self, agents: Sequence[str]) -> dict[str, dict[str, object]]:
        """Every robot's observation keyed by ``agents`` (one name per robot, in order).

        The robots share one read-only ``steps_left`` array (the team's clock)."""
        n, e = self.node_offsets.tolist(), self.edge_offsets.tolist()
        nodes, attr, links = self.nodes, self.edge_attr, self.edge_links
        new = tuple.__new__  # a GraphInstance without its constructor's overhead
        graphs = [
            new(GraphInstance, (nodes[a:b], attr[c:d], links[c:d]))
            for a, b, c, d in zip(n, n[1:], e, e[1:])  # noqa: B905 (n, e: one longer than R)
        ]
        clocks = set(self.steps_left.tolist())
        if len(clocks) == 1:
            shared = np.array(clocks.pop(), dtype=np.int64)
            shared.flags.writeable = False
            steps_left = [shared] * self.num_robots
        else:
            steps_left = [self.steps_left[i, ...] for i in range(self.num_robots)]
        return {
            agent: {"graph": graph, "action_mask": mask, "steps_left": clock}
            for agent, graph, mask, clock in zip(
                agents, graphs, list(self.action_mask), steps_left, strict=True
            )
        }

    def action_edges(self) -> np.ndarray:
        """Row of each robot's in-edge of each action slot in the edge tables, ``(R, 5)``
        int64, ``-1`` where the slot has no waypoint."""
        mask = self.action_mask.astype(bool)
        rank = np.cumsum(mask, axis=1) - 1  # rank of each real slot among the real ones
        return np.where(mask, self.edge_offsets[:-1, None] + rank, -1)

    def flat_graph(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every ego-graph as one disjoint graph: ``nodes (V, 6)``, ``edge_index (2, E)`` in
        table rows (``[sender; receiver]``), ``edge_attr (E, 1)``."""
        counts = np.diff(self.edge_offsets)
        shift = np.repeat(self.node_offsets[:-1], counts)  # (E,) first node of each edge's graph
        return self.nodes, (self.edge_links + shift[:, None]).T, self.edge_attr

    def to_padded(self, shape: PaddedShape) -> dict[str, np.ndarray]:
        """The padded observations (:func:`marl_cover.ego.build_ego_graphs`' arrays and
        ``steps_left``), batched over robots: the same arrays as the padded mode.

        Raises:
            ValueError: an ego-graph does not fit ``shape``, naming the robot and both sizes.
        """
        r, m, e = self.num_robots, shape.max_nodes, shape.max_edges
        num_nodes, num_edges = np.diff(self.node_offsets), np.diff(self.edge_offsets)
        mask = self.action_mask.astype(bool)
        num_rest = num_edges - 2 * mask.sum(axis=1)  # edges after the action edges
        _check_fits(num_nodes, m - 1, "nodes")
        _check_fits(NUM_EGO_ACTION_EDGES + num_rest, e, "edges")
        node_mask = np.arange(m) < num_nodes[:, None]  # (R, M)
        edge_mask = np.zeros((r, e), dtype=bool)
        edge_mask[:, :NUM_ACTIONS] = mask
        edge_mask[:, NUM_ACTIONS:NUM_EGO_ACTION_EDGES] = mask
        edge_mask[:, NUM_EGO_ACTION_EDGES:] = (
            np.arange(e - NUM_EGO_ACTION_EDGES) < num_rest[:, None]
        )
        nodes = np.zeros((r, m, NUM_NODE_FEATURES), dtype=np.float32)
        nodes[node_mask] = self.nodes[:, :NUM_NODE_FEATURES]
        node_pos = np.zeros((r, m, 2), dtype=np.float32)
        node_pos[node_mask] = self.nodes[:, NUM_NODE_FEATURES:]
        edge_index = np.full((r, e, 2), m - 1, dtype=np.int64)
        edge_index[edge_mask] = self.edge_links
        edge_attr = np.zeros((r, e, 1), dtype=np.float32)
        edge_attr[edge_mask] = self.edge_attr
        return {
            "nodes": nodes,
            "node_pos": node_pos,
            "node_mask": node_mask,
            "edge_index": np.ascontiguousarray(edge_index.transpose(0, 2, 1)),
            "edge_attr": edge_attr,
            "edge_mask": edge_mask,
            "action_mask": self.action_mask.copy(),
            "steps_left": self.steps_left.copy(),
        }


def _check_fits(counts: np.ndarray, bound: int, what: str) -> None:
    """Raises ``ValueError`` naming the first robot whose ego-graph has more ``what`` than
    ``bound``."""
    over = np.flatnonzero(counts > bound)
    if len(over):
        i = int(over[0])
        raise ValueError(
            f"the ego-graph of robot {i} has {counts[i]} {what}, more than the padded bound {bound}"
        )


def padded_to_compact(batch: dict[str, np.ndarray]) -> CompactObservations:
    """The compact tables of padded observations batched over robots (the inverse of
    :meth:`CompactObservations.to_padded`): the real nodes and edges, in order.

    Raises:
        KeyError: ``batch`` lacks a key of the padded observation, naming it.
    """
    missing = [k for k in (*PADDED_KEYS, "steps_left") if k not in batch]
    if missing:
        raise KeyError(f"padded observations need the keys {missing}")
    node_mask, edge_mask = batch["node_mask"].astype(bool), batch["edge_mask"].astype(bool)
    nodes = np.concatenate([batch["nodes"], batch["node_pos"]], axis=-1)[node_mask]
    return CompactObservations(
        node_offsets=_offsets(node_mask.sum(axis=1)),
        nodes=np.ascontiguousarray(nodes, dtype=np.float32),
        edge_offsets=_offsets(edge_mask.sum(axis=1)),
        edge_links=np.ascontiguousarray(
            batch["edge_index"].transpose(0, 2, 1)[edge_mask], dtype=np.int32
        ),
        edge_attr=np.ascontiguousarray(batch["edge_attr"][edge_mask], dtype=np.float32),
        action_mask=np.asarray(batch["action_mask"], dtype=np.int8).copy(),
        steps_left=np.asarray(batch["steps_left"], dtype=np.int64).copy(),
    )


def observation_to_padded(observation: dict, shape: PaddedShape) -> dict[str, np.ndarray]:
    """One agent's compact observation as its padded observation (the padded mode's ``Dict``).

    Raises:
        ValueError: the ego-graph does not fit ``shape``.
    """
    graph = observation["graph"]
    tables = CompactObservations(
        node_offsets=np.array([0, len(graph.nodes)], dtype=np.int64),
        nodes=np.asarray(graph.nodes, dtype=np.float32),
        edge_offsets=np.array([0, len(graph.edges)], dtype=np.int64),
        edge_links=np.asarray(graph.edge_links, dtype=np.int32),
        edge_attr=np.asarray(graph.edges, dtype=np.float32),
        action_mask=np.asarray(observation["action_mask"], dtype=np.int8)[None],
        steps_left=np.asarray(observation["steps_left"], dtype=np.int64)[None],
    )
    return {key: value[0, ...] for key, value in tables.to_padded(shape).items()}


#: Buffer sets a builder keeps (the observations of two earlier steps may still be alive).
_POOL_SIZE = 3


def _offsets(counts: np.ndarray) -> np.ndarray:
    """CSR offsets ``(len(counts) + 1,)`` int64 of ``counts``."""
    offsets = np.zeros(len(counts) + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    return offsets


class CompactBuilder:
    """Builds one map's compact observations step after step (the environment keeps one).

    The compiled kernel writes into tables sized from the previous step (grown and retried when
    a step needs more); the returned arrays are views of their used part, so what a step
    returns is exactly its ego-graphs. Without numba, the padded arrays are built and
    compacted (:func:`padded_to_compact`), which gives the same tables.

    Args:
        graph: The map.
        hops: Radius of the ego-graphs.
        shape: The padded bound of one ego-graph (caps the tables' growth).
        scratch: The compiled kernels' search tables of the map (the environment's own), or
            ``None`` without numba.
    """

    def __init__(
        self, graph: SpatialGraph, hops: int, shape: PaddedShape, scratch: EgoScratch | None
    ) -> None:
        self.graph = graph
        self.hops = hops
        self.shape = shape
        self._scratch = scratch
        self._node_capacity = 0
        self._edge_capacity = 0
        self._pool: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def _buffers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Node, link and length buffers of the current capacities: a set of an earlier step
        that nothing refers to any more (no observation of it is alive), or new ones. Reusing
        one spares the operating system's page faults of fresh memory, a tenth of a step."""
        for entry in self._pool:
            large = len(entry[0]) >= self._node_capacity and len(entry[1]) >= self._edge_capacity
            if large and unreferenced(entry):
                return entry
        entry = (
            np.empty((self._node_capacity, len(COMPACT_NODE_COLUMNS)), dtype=np.float32),
            np.empty((self._edge_capacity, 2), dtype=np.int32),
            np.empty((self._edge_capacity, 1), dtype=np.float32),
        )
        kept = [e for e in self._pool if not unreferenced(e)]  # still in use: not ours to free
        self._pool = [*kept[-(_POOL_SIZE - 1) :], entry]
        return entry

    def build(
        self,
        robot_node: np.ndarray,
        waypoint_features: np.ndarray,
        steps_left: int,
        neighbors: np.ndarray | None = None,
    ) -> CompactObservations:
        """Every robot's ego-graph (arguments as :func:`marl_cover.ego.build_ego_graphs`)."""
        num_robots = len(robot_node)
        clock = np.full(num_robots, steps_left, dtype=np.int64)
        if self._scratch is None:  # without numba
            batch = build_ego_graphs(
                self.graph, robot_node, waypoint_features, self.hops, self.shape, "numpy", neighbors
            )
            return padded_to_compact({**batch, "steps_left": clock})
        from marl_cover._ego_numba import OK, TOO_MANY_NODES, fill_compact

        graph, scratch = self.graph, self._scratch
        node_bound = num_robots * (self.shape.max_nodes - 1)
        edge_bound = num_robots * self.shape.max_edges
        if self._node_capacity == 0:  # a first guess: a quarter of the padded bound
            self._node_capacity = max(1, node_bound // 4)
            self._edge_capacity = max(1, edge_bound // 4)
        node_offsets = np.empty(num_robots + 1, dtype=np.int64)
        edge_offsets = np.empty(num_robots + 1, dtype=np.int64)
        action_mask = np.zeros((num_robots, NUM_ACTIONS), dtype=np.int8)
        while True:
            nodes, links, attr = self._buffers()
            tables: tuple[np.ndarray, ...] = (
                node_offsets,
                nodes,
                edge_offsets,
                links,
                attr,
                action_mask,
            )
            status = fill_compact(
                graph.neighbors if neighbors is None else neighbors,
                graph.neighbor_distances,
                graph.float_cells,
                np.ascontiguousarray(waypoint_features, dtype=np.float32),
                np.asarray(robot_node, dtype=np.int64),
                self.hops,
                *scratch.arrays(),
                *tables,
            )
            if status == OK:
                break
            full = (self._node_capacity, self._edge_capacity) == (node_bound, edge_bound)
            if full:
                raise RuntimeError("an ego-graph is larger than the padded bound of the map")
            if status == TOO_MANY_NODES:
                self._node_capacity = min(node_bound, 2 * self._node_capacity)
            else:
                self._edge_capacity = min(edge_bound, 2 * self._edge_capacity)
        num_nodes, num_edges = int(node_offsets[-1]), int(edge_offsets[-1])
        return CompactObservations(
            node_offsets=node_offsets,
            nodes=nodes[:num_nodes],
            edge_offsets=edge_offsets,
            edge_links=links[:num_edges],
            edge_attr=attr[:num_edges],
            action_mask=action_mask,
            steps_left=clock,
        )
