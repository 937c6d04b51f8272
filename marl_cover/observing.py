"""The observing half of the environment: every robot's ego-graph (padded or compact) and
the memory bound of one step's observations, as a mixin of :class:`marl_cover.env.CoverageEnv`."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from marl_cover.compact import CompactBuilder, CompactObservations
from marl_cover.ego import NUM_ACTIONS, EgoScratch, PaddedShape, build_ego_graphs

if TYPE_CHECKING:
    from marl_cover.config import CoverageConfig
    from marl_cover.discovery import Discovery
    from marl_cover.graph import SpatialGraph


class EpisodeObservations:
    """Observations of a :class:`marl_cover.env.CoverageEnv` (see its docstring)."""

    config: CoverageConfig
    possible_agents: list[str]
    _ego_shape: PaddedShape
    _ego_backend: str
    _robot_node: np.ndarray  # (R,)
    _discovery: Discovery | None
    _scratch: EgoScratch | None
    _compact_builder: CompactBuilder | None

    def _episode_map(self) -> SpatialGraph:
        raise NotImplementedError

    def _view(self) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def _steps_left(self) -> int:
        raise NotImplementedError

    @property
    def padded_shape(self) -> PaddedShape:
        """The padded sizes of one ego-graph (``M`` nodes with the sink, ``E`` edges): what
        :meth:`CompactObservations.to_padded` and ``observation_to_padded`` pad to."""
        return self._ego_shape

    def observation_bytes_bound(self) -> int:
        """Most bytes the observations of one step can take: the padded arrays (exact), or the
        compact tables when every ego-graph is as large as the padded bound allows."""
        m, e = self._ego_shape.max_nodes, self._ego_shape.max_edges
        per_robot_fixed = NUM_ACTIONS + 8  # action_mask, steps_left
        if self.config.observation_mode == "padded":
            per_robot = m * (4 * 4 + 2 * 4 + 1) + e * (2 * 8 + 4 + 1) + per_robot_fixed
        else:  # nodes (6 float32), links (2 int32), lengths (float32), two offsets
            per_robot = (m - 1) * 6 * 4 + e * (2 * 4 + 4) + 2 * 8 + per_robot_fixed
        return self.config.num_robots * per_robot

    def _check_memory(self) -> None:
        """Refuses, before anything is allocated, observations above ``max_observation_bytes``.

        Raises:
            ValueError: naming the bound, the limit, and what to change.
        """
        limit = self.config.max_observation_bytes
        need = self.observation_bytes_bound()
        if limit is not None and need > limit:
            config = self.config
            raise ValueError(
                f"{config.num_robots} robots with hops={config.hops} and "
                f"observation_mode={config.observation_mode!r} may need {need / 2**20:,.0f} MiB "
                f"of observations a step, above max_observation_bytes={limit} "
                f"({limit / 2**20:,.0f} MiB); use observation_mode='compact', fewer hops, or "
                "raise max_observation_bytes (None: no limit)"
            )

    def observations(self) -> dict[str, dict[str, Any]]:
        """Every robot's observation keyed by agent, as ``reset`` and ``step`` return them
        (fresh arrays; in compact mode, views of fresh step-wide tables)."""
        if self.config.observation_mode == "compact":
            return self.observe_compact().observations(self.possible_agents)
        batch = self.observe_batch()
        return {
            agent: {key: value[i, ...] for key, value in batch.items()}  # steps_left: 0-d
            for i, agent in enumerate(self.possible_agents)
        }

    def observe_compact(self) -> CompactObservations:
        """Every robot's ego-graph in compact step-wide tables (fresh arrays, in either
        observation mode; see :mod:`marl_cover.compact`)."""
        graph = self._episode_map()
        if self._compact_builder is None:
            self._compact_builder = CompactBuilder(
                graph, self.config.hops, self._ego_shape, self._scratch
            )
        robot_node, features = self._view()
        return self._compact_builder.build(
            robot_node,
            features,
            self._steps_left(),
            None if self._discovery is None else self._discovery.neighbors,
        )

    def observe_batch(self) -> dict[str, np.ndarray]:
        """Every robot's padded observation stacked on a leading robot axis (fresh arrays, in
        either observation mode)."""
        graph = self._episode_map()
        robot_node, features = self._view()
        batch = build_ego_graphs(
            graph,
            robot_node,
            features,
            self.config.hops,
            self._ego_shape,
            self._ego_backend,
            None if self._discovery is None else self._discovery.neighbors,
            self._scratch,
        )
        batch["steps_left"] = np.full(len(self._robot_node), self._steps_left(), dtype=np.int64)
        return batch
