"""Compact expert datasets: the graph once per episode, then robot positions and actions.

An episode stores its map (neighbour table, grid cells, cell size), its points of interest (as
bits), the robots' waypoints before every step ``(T + 1, R)`` and the actions ``(T, R)``.
Everything else is derived: the visited set at step ``t`` is the union of the waypoints the
robots stood on up to ``t``, in exploration the discovered set is the union of their sensor
footprints (so an omniscient expert's coverage dataset is also its exploration dataset: the
expert ignores discovery and the environment draws the same episodes), and observations are
rebuilt on demand with the environment's own ego-graph builder. About 6 kB per 228-waypoint
episode, where the paper stored 120 kB per step.

Episodes are grouped in shards (``shard_00000.npz``...), each covering a fixed range of episode
seeds, written to a temporary file and renamed; the folder's ``manifest.json`` records each
shard's SHA-256. An interrupted collection resumes by keeping the shards that match the
manifest and re-collecting the others: no episode is lost, written twice or half-read.
"""

from __future__ import annotations

import hashlib
import io
import json
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from marl_cover.agents.io import file_sha256, read_json, write_bytes_atomic, write_text_atomic
from marl_cover.discovery import discovery_steps, frontier_of, known_neighbors, sensor_footprints
from marl_cover.ego import PaddedShape, build_ego_graphs, waypoint_features
from marl_cover.env import CoverageEnv
from marl_cover.errors import BadFileError, MissingFileError
from marl_cover.graph import SpatialGraph

SHARD_PATTERN = "shard_{:05d}.npz"


@dataclass(frozen=True)
class Episode:
    """One recorded episode.

    Attributes:
        seed: Episode seed.
        graph: The map.
        interest: ``(N,)`` bool, points of interest.
        robot_node: ``(T + 1, R)`` waypoints before each step and after the last.
        actions: ``(T, R)`` int8 actions taken (labels, in DAgger episodes); ``-1`` where a
            robot has no label (it did not decide at that state: asynchronous missions,
            :mod:`marl_cover.agents.mission.dagger`).
        fallbacks: Steps on which a robot used the expert's greedy fallback.
        accept: ``(T, R)`` int8 bit masks of the actions the labelling expert rated as good
            as ``actions`` (bit ``a`` for action ``a``: every first hop of a shortest path to
            its next stop, :func:`marl_cover.agents.experts.expert.shortest_moves`), or ``None``
            (not recorded; :func:`trajectory_ties` infers them from an expert's own trajectory).
    """

    seed: int
    graph: SpatialGraph
    interest: np.ndarray
    robot_node: np.ndarray
    actions: np.ndarray
    fallbacks: int = 0
    accept: np.ndarray | None = None

    def label_sets(self) -> np.ndarray:
        """Bit masks ``(T, R)`` int64 of the actions as good as each label: :attr:`accept`
        where recorded, else the label's bit alone."""
        if self.accept is not None:
            return self.accept.astype(np.int64)
        actions = self.actions.astype(np.int64)
        return np.where(actions >= 0, 1 << actions.clip(min=0), 0)

    @property
    def num_steps(self) -> int:
        """Actions recorded (the episode's steps)."""
        return int(self.actions.shape[0])

    def visited(self, step: int) -> np.ndarray:
        """Waypoints visited before action ``step``, ``(N,)`` bool."""
        visited = np.zeros(self.graph.num_nodes, dtype=bool)
        visited[self.robot_node[: step + 1].ravel()] = True
        return visited

    def reward(self) -> int:
        """Points of interest visited during the episode (start waypoints excluded)."""
        return int(
            (self.interest & self.visited(self.num_steps)).sum()
            - (self.interest[self.robot_node[0]]).sum()
        )

    def discovery_steps(self, sensor_range: float) -> np.ndarray:
        """Exploration: when each waypoint became known, ``(N,)`` (the recorded positions and the
        sensor range determine it); the team knew ``discovery_steps(...) <= t`` before action
        ``t`` (see :func:`marl_cover.discovery.discovery_steps`)."""
        return discovery_steps(sensor_footprints(self.graph, sensor_range), self.robot_node)

    def observations(
        self,
        step: int,
        hops: int,
        shape: PaddedShape,
        backend: str = "numpy",
        sensor_range: float | None = None,
        max_steps: int | None = None,
    ) -> dict[str, np.ndarray]:
        """Every robot's ego-observation before action ``step``, stacked over robots
        (exploration when ``sensor_range`` is given; with ``max_steps``, the actions per episode,
        the clock ``steps_left`` too)."""
        features = waypoint_features(self.interest & ~self.visited(step))
        neighbors = None
        if sensor_range is not None:
            discovered = self.discovery_steps(sensor_range) <= step
            features[:, 3] = frontier_of(self.graph, discovered)
            neighbors = known_neighbors(self.graph, discovered)
        batch = build_ego_graphs(
            self.graph, self.robot_node[step], features, hops, shape, backend, neighbors
        )
        if max_steps is not None:
            batch["steps_left"] = np.full(len(self.robot_node[step]), max_steps - step, np.int64)
        return batch


def record_episode(env: CoverageEnv, policy, seed: int) -> Episode:  # noqa: ANN001
    """Plays one episode of ``policy`` (an expert with ``act_env``) and records it."""
    if hasattr(policy, "reset"):
        policy.reset(seed)
    env.reset(seed=seed)
    start = env.snapshot()
    positions, actions = [start.robot_node.copy()], []
    while env.agents:
        chosen = policy.act_env(env)
        actions.append([chosen[a] for a in env.possible_agents])
        env.step(chosen)
        positions.append(env.snapshot().robot_node.copy())
    return Episode(
        seed=seed,
        graph=start.graph,
        interest=start.interest.copy(),
        robot_node=np.array(positions, dtype=np.int32),
        actions=np.array(actions, dtype=np.int8),
        fallbacks=int(getattr(policy, "counts", {}).get("fallback_steps", 0)),
    )


def _pack(episodes: list[Episode]) -> dict[str, Any]:
    """Ragged episodes as flat arrays with offsets."""
    nodes = np.cumsum([0] + [e.graph.num_nodes for e in episodes])
    steps = np.cumsum([0] + [e.num_steps for e in episodes])
    arrays = {
        "seed": np.array([e.seed for e in episodes], dtype=np.int64),
        "fallbacks": np.array([e.fallbacks for e in episodes], dtype=np.int64),
        "cell_size": np.array([e.graph.cell_size for e in episodes], dtype=np.float64),
        "node_offsets": nodes.astype(np.int64),
        "step_offsets": steps.astype(np.int64),
        "neighbors": np.concatenate([e.graph.neighbors for e in episodes]).astype(np.int32),
        "positions": np.concatenate([e.graph.positions for e in episodes]).astype(np.float32),
        "interest_bits": np.packbits(np.concatenate([e.interest for e in episodes])),
        # robot waypoints: T + 1 rows per episode, so row offsets are step_offsets + index
        "robot_node": np.concatenate([e.robot_node for e in episodes]).astype(np.int32),
        "actions": np.concatenate([e.actions for e in episodes]).astype(np.int8),
    }
    if episodes and all(e.accept is not None for e in episodes):
        arrays["accept"] = np.concatenate([e.accept for e in episodes]).astype(np.int8)
    return arrays


def _unpack(arrays: dict[str, np.ndarray]) -> list[Episode]:
    nodes, steps = arrays["node_offsets"], arrays["step_offsets"]
    interest = np.unpackbits(arrays["interest_bits"], count=int(nodes[-1])).astype(bool)
    episodes = []
    for i, seed in enumerate(arrays["seed"].tolist()):
        n0, n1, s0, s1 = nodes[i], nodes[i + 1], steps[i], steps[i + 1]
        graph = SpatialGraph(
            arrays["positions"][n0:n1].astype(np.float64),
            arrays["neighbors"][n0:n1].astype(np.int64),
            float(arrays["cell_size"][i]),
        )
        episodes.append(
            Episode(
                seed=seed,
                graph=graph,
                interest=interest[n0:n1],
                robot_node=arrays["robot_node"][s0 + i : s1 + i + 1].astype(np.int64),
                actions=arrays["actions"][s0:s1],
                fallbacks=int(arrays["fallbacks"][i]),
                accept=arrays["accept"][s0:s1] if "accept" in arrays else None,
            )
        )
    return episodes


def trajectory_ties(episode: Episode) -> np.ndarray:
    """Bit masks ``(T, R)`` of the actions as good as each recorded one, from the trajectory.

    A robot's next reward is the first later step at which it stands on a point of interest
    nobody visited before. Where it got there along a shortest path (``j`` steps for a hop
    distance of ``j``), every first hop of a shortest path to that point arrives as early and
    is accepted; elsewhere (blocked, waiting, wandering, no reward ahead) only the recorded
    action is. Meant for an expert's own episodes, whose moves follow shortest paths between
    its stops; a DAgger episode records the labelling expert's sets instead
    (:attr:`Episode.accept`), since its trajectory is the learner's.
    """
    if (episode.actions < 0).any():
        raise ValueError(f"episode {episode.seed} has unlabelled robots; it must record accept")
    steps, num_robots = episode.actions.shape
    nodes = episode.robot_node  # (T + 1, R)
    first_visit = np.full(episode.graph.num_nodes, steps + 1, dtype=np.int64)
    for t in range(steps, -1, -1):  # earliest step each waypoint was stood on
        first_visit[nodes[t]] = t
    new_visit = episode.interest[nodes] & (first_visit[nodes] == np.arange(steps + 1)[:, None])
    # the next step after t at which robot r scores (-1: none), (T, R)
    scores_at = np.full((steps, num_robots), -1, dtype=np.int64)
    upcoming = np.full(num_robots, -1, dtype=np.int64)
    for t in range(steps - 1, -1, -1):
        upcoming = np.where(new_visit[t + 1], t + 1, upcoming)
        scores_at[t] = upcoming
    robots = np.arange(num_robots)
    here = nodes[:-1]  # (T, R)
    goal = nodes[scores_at.clip(min=0), robots]  # (T, R)
    ahead = scores_at - np.arange(steps)[:, None]  # (T, R) steps to get there
    distances = episode.graph.hop_distances(np.arange(episode.graph.num_nodes))  # (N, N)
    nbr = episode.graph.neighbors[here]  # (T, R, 4)
    on_path = (nbr >= 0) & (distances[nbr.clip(min=0), goal[..., None]] == ahead[..., None] - 1)
    bits = (on_path * (1 << np.arange(1, 5))).sum(-1)  # (T, R)
    labels = episode.actions.astype(np.int64)
    keep = (scores_at >= 0) & (distances[here, goal] == ahead) & ((bits >> labels) & 1 == 1)
    return np.where(keep, bits, 1 << labels).astype(np.int8)


def write_shard(path: Path, episodes: list[Episode]) -> str:
    """Writes episodes to ``path`` atomically (a temporary file in the same folder, renamed).

    Returns:
        The SHA-256 of the bytes written, for the dataset's :class:`ShardManifest`.
    """
    data = shard_bytes(episodes)
    write_bytes_atomic(path, data)
    return hashlib.sha256(data).hexdigest()


def shard_bytes(episodes: list[Episode]) -> bytes:
    """The bytes of a shard file holding ``episodes`` (what :func:`write_shard` writes)."""
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **_pack(episodes))
    return buffer.getvalue()


def read_shard(path: Path, sha256: str | None = None) -> list[Episode]:
    """The episodes of one shard, read whole (every array's CRC checked) or not at all.

    Args:
        path: The shard.
        sha256: The digest the dataset's manifest records for it, checked first.

    Raises:
        MissingFileError: there is no file at ``path``.
        BadFileError: the file is not a whole shard (truncated, corrupted, another kind of
            file) or its digest is not ``sha256``, naming it and what is wrong.
    """
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(path, "no dataset shard here")
    data = path.read_bytes()  # read once: hashed and parsed from memory, no handle kept
    if sha256 is not None:
        found = hashlib.sha256(data).hexdigest()
        if found != sha256:
            raise BadFileError(path, f"SHA-256 is {found}, the manifest records {sha256}")
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as arrays:
            return _unpack({k: arrays[k] for k in arrays.files})
    except Exception as error:  # noqa: BLE001 (zip, zlib, numpy and shape errors alike)
        raise BadFileError(
            path, f"not a whole dataset shard ({type(error).__name__}: {error})"
        ) from error


class ShardManifest:
    """A dataset folder's ``manifest.json``: each shard's SHA-256, seeds and episode count,
    plus the settings the dataset was made with; rewritten atomically as shards are added.

    Args:
        folder: The dataset's folder.
    """

    FILE = "manifest.json"

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)
        self.path = self.folder / self.FILE
        self.config: dict[str, Any] | None = None
        self.shards: dict[str, dict[str, Any]] = {}
        if self.path.exists():
            record = read_json(self.path)
            shards = record.get("shards") if isinstance(record, dict) else None
            if not isinstance(shards, dict) or not all(
                isinstance(v, dict) and isinstance(v.get("sha256"), str) for v in shards.values()
            ):
                raise BadFileError(self.path, "not a dataset manifest (no 'shards' with digests)")
            self.config, self.shards = record.get("config"), shards

    @property
    def exists(self) -> bool:
        """Whether the folder has a manifest on disk."""
        return self.path.exists()

    def save(self) -> None:
        """Writes the manifest atomically."""
        record = {"config": self.config, "shards": dict(sorted(self.shards.items()))}
        write_text_atomic(self.path, json.dumps(record, indent=1))

    def add(self, name: str, sha256: str, seeds: list[int]) -> None:
        """Records the shard ``name`` and saves the manifest."""
        self.shards[name] = {"sha256": sha256, "episodes": len(seeds), "seeds": seeds}
        self.save()

    def problem(self, name: str) -> str | None:
        """What is wrong with the shard ``name`` on disk (``None``: it is whole and recorded)."""
        path = self.folder / name
        if not path.is_file():
            return "missing"
        if name not in self.shards:
            return "not in the manifest (a collection stopped before recording it)"
        found, expected = file_sha256(path), self.shards[name]["sha256"]
        return None if found == expected else f"SHA-256 is {found}, the manifest has {expected}"


def load_dataset(folder: str | Path, bad_shards: str = "raise") -> list[Episode]:
    """Every episode of a dataset folder, ordered by seed.

    Each shard is checked against the folder's manifest (its SHA-256) and read whole. A
    folder without a manifest is read shard by shard, each array's CRC checked.

    Args:
        folder: The dataset's folder.
        bad_shards: ``"raise"``: a bad shard is an error; ``"skip"``: it is left out with a
            warning naming it (``marl-cover collect`` with the same settings re-collects it).

    Raises:
        MissingFileError: no shards in ``folder``.
        BadFileError: a shard listed in the manifest is missing, fails its checksum or
            cannot be read (with ``bad_shards="raise"``), or the manifest is unreadable.
    """
    if bad_shards not in ("raise", "skip"):
        raise ValueError(f"bad_shards must be 'raise' or 'skip', got {bad_shards!r}")
    folder = Path(folder)
    manifest = ShardManifest(folder)
    if manifest.exists:
        names = sorted(manifest.shards)
    else:
        names = sorted(p.name for p in folder.glob("shard_*.npz"))
    if not names:
        raise MissingFileError(folder, "no dataset shards (shard_*.npz) in this folder")
    episodes = []
    for name in names:
        digest = manifest.shards[name]["sha256"] if manifest.exists else None
        try:
            episodes.extend(read_shard(folder / name, digest))
        except BadFileError as error:
            if bad_shards == "raise":
                raise BadFileError(
                    error.path,
                    f"{error.problem}; `marl-cover collect` with the dataset's settings "
                    f"and out={folder} collects it again, bad_shards=skip leaves it out",
                ) from None
            warnings.warn(f"skipped a bad shard: {error}", stacklevel=2)
    return sorted(episodes, key=lambda e: e.seed)
