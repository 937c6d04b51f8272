"""Ego-graph inspection: an observation back to a ``networkx`` graph, and a drawing of it.

Needs the ``render`` extra (networkx, matplotlib), imported lazily.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from marl_cover.ego import NODE_FEATURES


def ego_to_networkx(observation: dict[str, np.ndarray]) -> Any:
    """The real part of a padded graph observation as an undirected ``networkx.Graph``.

    Nodes keep their local index and carry ``kind`` (``"robot"`` or ``"waypoint"``), the four
    feature flags by name, ``pos`` (cells) and ``hops`` (hop distance from node 0, the ego
    robot). Edges carry ``length`` (cells) and ``action`` (``True`` for robot-waypoint edges).

    Raises:
        KeyError: a key of the observation is missing, naming it.
    """
    import networkx as nx

    for key in ("nodes", "node_pos", "node_mask", "edge_index", "edge_attr", "edge_mask"):
        if key not in observation:
            raise KeyError(f"observation has no key {key!r}")
    nodes, mask = observation["nodes"], observation["node_mask"].astype(bool)
    graph = nx.Graph()
    for i in np.flatnonzero(mask):
        flags = {name: bool(nodes[i, k]) for k, name in enumerate(NODE_FEATURES)}
        kind = "robot" if flags["is_robot"] else "waypoint"
        graph.add_node(int(i), kind=kind, pos=tuple(observation["node_pos"][i].tolist()), **flags)
    edges = observation["edge_index"][:, observation["edge_mask"].astype(bool)]
    lengths = observation["edge_attr"][observation["edge_mask"].astype(bool), 0]
    for (s, r), length in zip(edges.T.tolist(), lengths.tolist(), strict=True):
        action = graph.nodes[s]["kind"] != graph.nodes[r]["kind"]
        graph.add_edge(s, r, length=float(length), action=action)
    if 0 in graph:
        hops = nx.single_source_shortest_path_length(graph, 0)
        nx.set_node_attributes(graph, hops, "hops")
    return graph


def draw_ego(
    observation: dict[str, np.ndarray], path: str | Path, hops: int | None = None, title: str = ""
) -> Path:
    """Draws an ego-graph to an image file: the ego robot (red star), other robots (blue),
    waypoints (grey, orange if of interest) and the K-hop boundary (black rings).

    Args:
        observation: One robot's observation.
        path: Output image path (PNG recommended).
        hops: Radius K; nodes at exactly K hops are ringed. Default: the largest hop count.
        title: Figure title.

    Returns:
        The path written.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    graph = ego_to_networkx(observation)
    pos = {n: graph.nodes[n]["pos"] for n in graph}
    radius = hops if hops is not None else max(nx_hops(graph).values(), default=0)
    fig, ax = plt.subplots(figsize=(7, 7), dpi=100)
    segments = [(pos[s], pos[r]) for s, r in graph.edges]
    colours = ["#4e79a7" if graph.edges[e]["action"] else "#bbbbbb" for e in graph.edges]
    ax.add_collection(LineCollection(segments, colors=colours, linewidths=0.8, zorder=0))

    def scatter(selected: list[int], **style: Any) -> None:
        if selected:
            ax.scatter(*np.array([pos[n] for n in selected]).T, **style)

    waypoints = [n for n in graph if graph.nodes[n]["kind"] == "waypoint"]
    scatter(
        [n for n in waypoints if not graph.nodes[n]["is_interest"]],
        s=12,
        c="#bbbbbb",
        zorder=1,
        label="waypoint",
    )
    scatter(
        [n for n in waypoints if graph.nodes[n]["is_interest"]],
        s=22,
        c="#f28e2b",
        zorder=2,
        label="point of interest",
    )
    scatter(
        [n for n in waypoints if graph.nodes[n].get("hops") == radius],
        s=60,
        facecolors="none",
        edgecolors="black",
        zorder=3,
        label=f"{radius}-hop boundary",
    )
    scatter(
        [n for n in graph if graph.nodes[n]["kind"] == "robot" and n != 0],
        s=90,
        c="#4e79a7",
        marker="s",
        zorder=4,
        label="other robot",
    )
    scatter([0], s=250, c="#e15759", marker="*", zorder=5, label="ego robot")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_title(
        title or f"ego-graph: {graph.number_of_nodes()} nodes, {graph.number_of_edges()} edges"
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def nx_hops(graph: Any) -> dict[int, int]:
    """Hop distance of every node from the ego robot (from the ``hops`` node attribute)."""
    return {n: d for n, d in graph.nodes(data="hops") if d is not None}
