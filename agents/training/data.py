"""Expert transitions in TorchRL storage, and their collation into one flat graph per batch.

A transition is stored compactly (TensorDict fields, batch dim = transitions):
``episode`` (index into a per-episode graph table), ``step`` (actions taken before it),
``robot_node (R,)``, ``interest (N_max,)``
bool (unvisited points of interest before the action), ``action (R,)`` (the expert's label),
and in exploration ``discovered (N_max,)`` and ``frontier (N_max,)`` bool.
The graph of each episode is stored once (``neighbors (N_max, 4)``, ``distances (N_max, 4)``).

:func:`collate_states` turns a sampled batch into the whole-graph state encoding of
:class:`marl_cover.ego.StateBuilder` (robots, then waypoints; action edges target -> robot and
back; waypoint edges), all samples in one flat graph, so one GNN pass gives every robot's
logits (the centralized pass, equal to each robot's own ego-graph pass: tested).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
import torch
from tensordict import TensorDict

from marl_cover.agents.models.logits import with_time_feature
from marl_cover.agents.training.datasets import Episode
from marl_cover.discovery import frontier_of
from marl_cover.ego import NUM_ACTIONS, NUM_NODE_FEATURES
from marl_cover.graph import SpatialGraph


class GraphTable:
    """The graphs of many episodes, padded to the largest (``-1`` neighbour slots).

    Args:
        graphs: One graph per episode index.
        max_nodes: Pad to this many waypoints (default: the largest graph).
    """

    def __init__(self, graphs: Sequence[SpatialGraph], max_nodes: int | None = None) -> None:
        largest = max(g.num_nodes for g in graphs)
        self.max_nodes = max_nodes or largest
        if largest > self.max_nodes:
            raise ValueError(f"a graph has {largest} waypoints, more than max_nodes={max_nodes}")
        n = self.max_nodes
        neighbors = np.full((len(graphs), n, 4), -1, dtype=np.int64)
        distances = np.zeros((len(graphs), n, 4), dtype=np.float32)
        for i, graph in enumerate(graphs):
            neighbors[i, : graph.num_nodes] = graph.neighbors
            distances[i, : graph.num_nodes] = graph.neighbor_distances
        self.neighbors = torch.from_numpy(neighbors)  # (episodes, N_max, 4)
        self.distances = torch.from_numpy(distances)  # (episodes, N_max, 4)
        self.num_nodes = torch.tensor([g.num_nodes for g in graphs])  # (episodes,)

    def __len__(self) -> int:
        return len(self.num_nodes)

    def extended(self, graphs: Sequence[SpatialGraph]) -> GraphTable:
        """A table with ``graphs`` appended (indices ``len(self)`` onward)."""
        more = GraphTable(graphs, self.max_nodes)
        table = GraphTable.__new__(GraphTable)
        table.max_nodes = self.max_nodes
        table.neighbors = torch.cat([self.neighbors, more.neighbors])
        table.distances = torch.cat([self.distances, more.distances])
        table.num_nodes = torch.cat([self.num_nodes, more.num_nodes])
        return table


def episode_transitions(
    episodes: Iterable[Episode],
    max_nodes: int,
    first_index: int = 0,
    sensor_range: float | None = None,
) -> TensorDict:
    """Every step of ``episodes`` as transitions; episode ``i`` gets index ``first_index + i``.

    Each transition holds the label ``action (R,)`` and ``accept (R,)``, the bit masks of the
    actions as good as it (:attr:`Episode.accept`; the label's bit alone where not recorded).

    With ``sensor_range`` (exploration) each transition also holds what the team had
    discovered and the frontier.
    """
    names = ["episode", "step", "robot_node", "interest"]
    if sensor_range is not None:
        names += ["discovered", "frontier"]
    fields: dict[str, list[np.ndarray]] = {name: [] for name in names}
    actions, accepted = [], []
    for i, episode in enumerate(episodes):
        steps, n = episode.num_steps, episode.graph.num_nodes
        visited = np.zeros(n, dtype=bool)
        interest = np.zeros((steps, max_nodes), dtype=bool)
        for t in range(steps):
            visited[episode.robot_node[t]] = True
            interest[t, :n] = episode.interest & ~visited
        if sensor_range is not None:
            found = episode.discovery_steps(sensor_range)
            discovered = np.zeros((steps, max_nodes), dtype=bool)
            frontier = np.zeros((steps, max_nodes), dtype=bool)
            for t in range(steps):
                discovered[t, :n] = found <= t
                frontier[t, :n] = frontier_of(episode.graph, discovered[t, :n])
            fields["discovered"].append(discovered)
            fields["frontier"].append(frontier)
        fields["episode"].append(np.full(steps, first_index + i, dtype=np.int64))
        fields["step"].append(np.arange(steps, dtype=np.int64))
        fields["robot_node"].append(episode.robot_node[:steps].astype(np.int64))
        fields["interest"].append(interest)
        actions.append(episode.actions.astype(np.int64))
        accepted.append(episode.label_sets())
    data = {k: torch.from_numpy(np.concatenate(v)) for k, v in fields.items()}
    data["action"] = torch.from_numpy(np.concatenate(actions))
    data["accept"] = torch.from_numpy(np.concatenate(accepted))
    return TensorDict(data, batch_size=[len(data["episode"])])


def collate_states(
    batch: TensorDict,
    table: GraphTable,
    time_horizon: int | None = None,
    max_steps: int | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """One flat graph holding the state of every sampled transition.

    Args:
        batch: Transitions with ``episode (B,)``, ``robot_node (B, R)``, ``interest (B, N)``,
            and in exploration ``discovered (B, N)`` and ``frontier (B, N)``: undiscovered
            waypoints then have no features and no edges (isolated nodes change no robot's
            logits, so this equals the env's ``state()`` of discovered waypoints only).
        table: The graphs the ``episode`` indices refer to.
        time_horizon: A model's ``GNNConfig.time_horizon``: every node gets ``steps_left /
            time_horizon`` as a fifth feature, ``steps_left = max_steps - step``.
        max_steps: Actions per episode (default: ``time_horizon``).

    Returns:
        ``nodes (V, 4)`` (``(V, 5)`` with ``time_horizon``), ``edge_index (2, E)``,
        ``edge_attr (E, 1)``, and the flat edge id of each robot's action slots ``(B * R, 5)``
        (``-1`` where the slot has no waypoint).
    """
    episode, robot_node = batch["episode"], batch["robot_node"]
    num_samples, num_robots = robot_node.shape
    n = table.max_nodes
    per_sample = num_robots + n
    base = (torch.arange(num_samples) * per_sample).view(-1, 1)  # (B, 1)

    known = "discovered" in batch
    exists = torch.arange(n) < table.num_nodes[episode].view(-1, 1)  # (B, N)
    if known:
        exists = exists & batch["discovered"]
    nodes = torch.zeros(num_samples, per_sample, NUM_NODE_FEATURES)
    nodes[:, :num_robots, 0] = 1.0
    nodes[:, num_robots:, 1] = exists.float()
    nodes[:, num_robots:, 2] = (batch["interest"] & exists).float()
    if known:
        nodes[:, num_robots:, 3] = batch["frontier"].float()
    if time_horizon is not None:
        steps_left = (max_steps or time_horizon) - batch["step"]
        nodes = with_time_feature(nodes, steps_left, time_horizon)

    neighbors = table.neighbors[episode]  # (B, N, 4)
    distances = table.distances[episode]  # (B, N, 4)
    waypoint_valid = neighbors >= 0
    if known:  # only edges between two discovered waypoints
        rows = torch.arange(num_samples).view(-1, 1, 1)
        waypoint_valid &= exists.unsqueeze(-1) & exists[rows, neighbors.clamp(min=0)]
    owner = (base + num_robots + torch.arange(n).view(1, -1)).unsqueeze(-1).expand_as(neighbors)
    waypoint_senders = owner[waypoint_valid]
    waypoint_receivers = (base.unsqueeze(-1) + num_robots + neighbors)[waypoint_valid]
    waypoint_attr = distances[waypoint_valid]

    rows = torch.arange(num_samples).view(-1, 1)
    targets = torch.cat([robot_node.unsqueeze(-1), neighbors[rows, robot_node]], dim=-1)
    action_valid = (targets >= 0).reshape(-1)  # (B * R * 5,)
    action_attr = torch.cat(
        [torch.zeros(num_samples, num_robots, 1), distances[rows, robot_node]], dim=-1
    ).reshape(-1)
    target_ids = (base.unsqueeze(-1) + num_robots + targets.clamp(min=0)).reshape(-1)
    robot_ids = (base + torch.arange(num_robots)).unsqueeze(-1).expand_as(targets).reshape(-1)
    target_ids, robot_ids = target_ids[action_valid], robot_ids[action_valid]
    action_attr = action_attr[action_valid]

    edge_index = torch.cat(
        [
            torch.stack([target_ids, robot_ids]),  # action edges, target -> robot
            torch.stack([robot_ids, target_ids]),  # and back
            torch.stack([waypoint_senders, waypoint_receivers]),
        ],
        dim=1,
    )
    edge_attr = torch.cat([action_attr, action_attr, waypoint_attr]).unsqueeze(-1)
    new_id = torch.cumsum(action_valid.long(), 0) - 1
    action_edges = torch.where(action_valid, new_id, torch.full_like(new_id, -1))
    return (
        nodes.view(-1, nodes.shape[-1]),
        edge_index,
        edge_attr,
        action_edges.view(-1, NUM_ACTIONS),
    )
