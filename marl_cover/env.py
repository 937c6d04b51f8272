"""Multi-robot coverage and exploration on a spatial graph, as a PettingZoo parallel env.

A team of robots moves on a lattice of waypoints (5 m apart, 4-connected). Half of the
waypoints, drawn at each reset, are points of interest; the team earns +1 for each point of
interest that a robot visits for the first time. Each robot sees only its K-hop ego-graph.

Tasks (``task=``, one environment class): in ``"coverage"`` the whole map is known from the
start. In ``"exploration"`` a waypoint becomes known when it is within ``sensor_range`` metres
(default 22 m) of a robot's waypoint, at reset or after a step; knowledge is shared and
cumulative (:mod:`marl_cover.discovery`). Ego-graphs are then searched on the known graph only,
``state()`` holds only discovered waypoints (in discovery order) and known edges, and
``is_frontier`` marks discovered waypoints with an undiscovered neighbour. Rewards, moves and
the random draws of an episode are the same in both tasks.

========================  ==================================================================
Agents                    ``robot_0 ... robot_{num_robots-1}``
Action space              ``Discrete(5)``: 0 stay, 1 east, 2 north, 3 west, 4 south
Observation space         ``Dict`` of padded graph arrays (table below); with
                          ``observation_mode="compact"``, the same ego-graph unpadded, as a
                          ``Dict`` of a ``gymnasium.spaces.Graph`` (:mod:`marl_cover.compact`)
State space               ``Dict``: the whole (exploration: known) graph in the same encoding,
                          plus ``robot_nodes`` and ``steps_left``
Reward                    Team reward: points of interest newly visited this step (all robots
                          get it); each robot's own count is ``infos[agent]["new_interest"]``
Termination               Every point of interest has been visited
Truncation                After ``max_steps`` actions (default 50)
Import                    ``marl_cover.parallel_env(**config)``, ``marl_cover.env(**config)``
Registered ids            ``marl_cover/Coverage-v0`` (parallel and AEC registries)
========================  ==================================================================

Observation of one robot (``M`` = padded nodes, ``E`` = padded edges, fixed per environment;
the last node ``M - 1`` is a padding sink, and padded edges run sink -> sink):

==============  ===============  =======  ==================================================
key             shape            dtype    meaning
==============  ===============  =======  ==================================================
``nodes``       ``(M, 4)``       float32  ``[is_robot, is_waypoint, is_interest,
                                          is_frontier]``; ``is_interest`` = unvisited point
                                          of interest; ``is_frontier``: discovered with an
                                          undiscovered neighbour (always 0 in coverage).
                                          Node 0 is the ego robot (no ego-only feature)
``node_pos``    ``(M, 2)``       float32  position in cells relative to the ego robot
                                          (+x east, +y north); 0 for padding
``node_mask``   ``(M,)``         bool     real nodes (a prefix)
``edge_index``  ``(2, E)``       int64    ``[sender; receiver]`` local node indices
``edge_attr``   ``(E, 1)``       float32  edge length in cells (0 for a robot's stay edge)
``edge_mask``   ``(E,)``         bool     real edges; edges ``k`` and ``5 + k`` are the
                                          ego robot's action edge of slot ``k`` (target ->
                                          robot, robot -> target), real iff the slot exists
``action_mask`` ``(5,)``         int8     1 where the action leads to a waypoint
``steps_left``  ``()``           int64    actions left in the episode (the team's clock)
==============  ===============  =======  ==================================================

The ego-graph holds every node within ``hops`` hops of the ego robot in the graph of robots
and waypoints (each robot linked to its own waypoint and to its neighbours) and every edge
among them; see :mod:`marl_cover.ego`. ``state()`` has the same keys with robots as nodes
``0..R-1``, waypoints after them, ``node_pos`` in the map frame, ``action_mask (R, 5)``,
``robot_nodes (R,)`` and ``steps_left`` (``()`` int64, actions left in the episode: what a
centralized critic needs to value a state of a fixed-length episode).

Arguments: the fields of :class:`marl_cover.config.CoverageConfig`; ``max_cycles`` is accepted
as PettingZoo's name for ``max_steps``.

Deviations from the paper's code (exact episode length, explicit stay action, a resolver that
never lets two robots share a waypoint, ego-graphs instead of the whole map, one seeded
generator, counted no-ops for masked actions) are listed in ``docs/environment.md``.

Version history: v0, first release.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import numbers
import warnings
from typing import Any

import gymnasium
import numpy as np
from pettingzoo import ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec

from marl_cover.actions import read_actions
from marl_cover.collisions import resolve_collisions, resolve_collisions_compiled
from marl_cover.compact import CompactBuilder, compact_space
from marl_cover.config import CoverageConfig
from marl_cover.discovery import Discovery, sensor_footprints
from marl_cover.ego import (
    NUM_ACTIONS,
    EgoScratch,
    StateBuilder,
    ego_shape,
    graph_space,
    resolve_backend,
    state_shape,
    waypoint_features,
)
from marl_cover.generator import draw_interest, draw_starts
from marl_cover.graph import SpatialGraph
from marl_cover.observing import EpisodeObservations
from marl_cover.render import EpisodeRendering
from marl_cover.sources import make_map_source
from marl_cover.types import CoverageSnapshot, Moves, StepResult

#: Options ``reset`` understands.
RESET_OPTIONS = ("robot_nodes", "interest_nodes")


@dataclasses.dataclass(frozen=True)
class _EpisodeDraw:
    """What :meth:`CoverageEnv.reset` draws before it changes anything."""

    rng: np.random.Generator
    graph: SpatialGraph
    state_builder: StateBuilder | None
    footprint: Any
    interest: np.ndarray  # (num_nodes,) bool
    robot_node: np.ndarray  # (num_robots,) int64
    discovery: Discovery | None


class CoverageEnv(EpisodeRendering, EpisodeObservations, ParallelEnv):
    """The coverage environment; see the module docstring for its spaces and rules."""

    metadata = {
        "name": "marl_cover_coverage_v0",
        "render_modes": ["human", "rgb_array"],
        "render_fps": 4,
        "is_parallelizable": True,
    }

    #: Whether the robots' observed waypoints are always distinct (the resolver's promise),
    #: which bounds the robots of an ego-graph by its waypoints (:func:`ego_shape`).
    _DISTINCT_VIEW = True

    #: Attributes that no step changes, shared by :meth:`fork` (the spaces once built).
    _FORK_SHARED: tuple[str, ...] = (
        "config",
        "_map_source",
        "_graph",
        "_state_builder",
        "_footprint",
        "_observation_space",
        "_action_spaces",
        "state_space",
        "_ego_shape",
        "_state_shape",
        "_scratch",
        "_compact_builder",
    )

    def __init__(self, config: CoverageConfig | None = None, **overrides: Any) -> None:
        """Creates the environment.

        Args:
            config: A full configuration; ``overrides`` replace its fields.
            **overrides: Fields of :class:`CoverageConfig`, by name.
        """
        base = config or CoverageConfig()
        if overrides:
            values = {f.name: getattr(base, f.name) for f in dataclasses.fields(base)}
            base = CoverageConfig.from_dict({**values, **overrides})
        self.config = base
        self.render_mode = base.render_mode
        self.possible_agents = [f"robot_{i}" for i in range(base.num_robots)]
        self.agents: list[str] = []
        self._map_source = make_map_source(base)
        self._ego_backend = resolve_backend(base.ego_backend)
        self._ego_shape = ego_shape(
            self._map_source.max_waypoints,
            base.num_robots,
            base.hops,
            self._map_source.lattice,
            self._DISTINCT_VIEW,
        )
        self._state_shape = state_shape(
            self._map_source.max_waypoints, self._map_source.max_waypoint_edges, base.num_robots
        )
        self._check_memory()
        self._rng: np.random.Generator | None = None
        self._graph: SpatialGraph | None = None
        self._state_builder: StateBuilder | None = None
        self._footprint: Any = None  # exploration: sensor footprints of self._graph
        self._discovery: Discovery | None = None
        self._scratch: EgoScratch | None = None  # the ego kernels' search state, per map
        self._compact_builder: CompactBuilder | None = None  # per map, made on first use
        self._renderer: Any = None

    # ------------------------------------------------------------------ spaces
    # Built on first use: a planner that makes many small environments never reads them.
    @functools.cached_property
    def _observation_space(self) -> gymnasium.spaces.Dict:
        if self.config.observation_mode == "compact":
            return compact_space(self.config.max_steps)
        action_mask = gymnasium.spaces.Box(0, 1, (NUM_ACTIONS,), np.int8)
        clock = gymnasium.spaces.Box(0, self.config.max_steps, (), np.int64)  # steps_left
        return graph_space(self._ego_shape, {"action_mask": action_mask, "steps_left": clock})

    @functools.cached_property
    def _action_spaces(self) -> dict[str, gymnasium.spaces.Discrete]:
        return {a: gymnasium.spaces.Discrete(NUM_ACTIONS) for a in self.possible_agents}

    @functools.cached_property
    def state_space(self) -> gymnasium.spaces.Dict:
        """The space of :meth:`state` (one object)."""
        r = self.config.num_robots
        return graph_space(
            self._state_shape,
            {
                "action_mask": gymnasium.spaces.Box(0, 1, (r, NUM_ACTIONS), np.int8),
                "robot_nodes": gymnasium.spaces.Box(
                    0, self._state_shape.max_nodes - 1, (r,), np.int64
                ),
                "steps_left": gymnasium.spaces.Box(0, self.config.max_steps, (), np.int64),
            },
        )

    @property
    def max_waypoints(self) -> int:
        """Most waypoints of any map this environment can draw (the padding bound)."""
        return self._map_source.max_waypoints

    def observation_space(self, agent: str) -> gymnasium.spaces.Dict:
        """The observation space of ``agent`` (one shared object)."""
        self._agent_index(agent)
        return self._observation_space

    def action_space(self, agent: str) -> gymnasium.spaces.Discrete:
        """The action space of ``agent`` (one object per agent, cached)."""
        self._agent_index(agent)
        return self._action_spaces[agent]

    @functools.cached_property
    def _agent_indices(self) -> dict[str, int]:
        return {a: i for i, a in enumerate(self.possible_agents)}

    def _agent_index(self, agent: str) -> int:
        try:
            return self._agent_indices[agent]
        except KeyError:
            raise KeyError(f"unknown agent {agent!r}; agents are {self.possible_agents}") from None

    # ------------------------------------------------------------------ episode
    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, dict[str, Any]]]:
        """Starts an episode: draws the map, the points of interest and the start waypoints.

        Args:
            seed: Seeds the environment's generator (a new one from OS entropy on the first
                reset without a seed; later resets without a seed continue the generator).
            options: ``robot_nodes`` (start waypoints, one per robot) and ``interest_nodes``
                (the points of interest) fix those draws; other keys are ignored with a warning.

        Raises:
            ValueError: a bad seed or option, naming it and its first bad entry, or a drawn
                map this environment cannot use. The environment is then exactly as before
                the call, its generator included.
        """
        self._start_episode(seed, options)
        zeros = np.zeros(self.config.num_robots, dtype=np.int64)
        infos = self._infos(zeros, zeros.astype(bool), zeros.astype(bool))
        return self.observations(), infos

    def _start_episode(self, seed: int | None, options: dict[str, Any] | None) -> None:
        """The draws and the episode state of :meth:`reset`, without building observations
        (subclasses that extend the state observe once, after their own part).

        All or nothing: the episode is drawn and checked first (:meth:`_draw_episode`), and
        only then replaces the environment's state, so a reset that raises leaves the
        environment, its generator included, exactly as it was.
        """
        draw = self._draw_episode(seed, options)
        self._rng = draw.rng
        if draw.graph is not self._graph:
            self._graph = draw.graph
            self._state_builder = draw.state_builder
            self._footprint = draw.footprint
            self._scratch = EgoScratch(draw.graph) if self._ego_backend == "numba" else None
            self._compact_builder = None  # made on the map's first observe_compact()
        self._interest = draw.interest
        self._robot_node = draw.robot_node
        self._visited = np.zeros(draw.graph.num_nodes, dtype=bool)
        self._visited[self._robot_node] = True
        self._interest_left = int(np.count_nonzero(self._interest & ~self._visited))
        self._waypoint_features = waypoint_features(self._interest & ~self._visited)
        self._discovery = draw.discovery
        self._sense()
        self._num_steps = 0
        self._credits = np.zeros(self.config.num_robots, dtype=np.int64)
        self._trails: list[np.ndarray] = [self._robot_node.copy()]
        self.agents = self.possible_agents[:]

    def _draw_episode(self, seed: int | None, options: dict[str, Any] | None) -> _EpisodeDraw:
        """The random draws of the next episode, checked, on a copy of the generator: nothing
        of the environment changes here.

        Raises:
            ValueError: a bad seed or option (naming it), or a drawn map the environment
                cannot use.
        """
        if seed is not None and not (isinstance(seed, numbers.Integral) and seed >= 0):
            raise ValueError(f"seed must be a non-negative integer or None, got {seed!r}")
        options = dict(options or {})
        for key in sorted(set(options) - set(RESET_OPTIONS)):
            warnings.warn(f"reset ignores unknown option {key!r}", stacklevel=4)
        rng = (
            np.random.default_rng(seed)
            if seed is not None or self._rng is None
            else copy.deepcopy(self._rng)
        )
        graph = self._map_source.sample(rng)
        state_builder, footprint = self._state_builder, self._footprint
        if graph is not self._graph:
            self._check_map(graph)
            state_builder = StateBuilder(graph, self.config.num_robots, self._state_shape)
            footprint = self._sensor_footprints(graph)
        config = self.config
        interest = draw_interest(
            graph, rng, config.interest_fraction, options.get("interest_nodes")
        )
        robot_node = draw_starts(
            graph, rng, config.num_robots, config.start_density, options.get("robot_nodes")
        )
        discovery = None if footprint is None else Discovery(graph, footprint)
        return _EpisodeDraw(rng, graph, state_builder, footprint, interest, robot_node, discovery)

    def _check_map(self, graph: SpatialGraph) -> None:
        """Checks a newly drawn map before an episode starts on it (subclasses add theirs).

        Raises:
            ValueError: the map cannot host an episode of this environment.
        """

    def _sensor_footprints(self, graph: SpatialGraph) -> Any:
        """Exploration: what a robot on each waypoint senses (``None`` in coverage)."""
        if self.config.task != "exploration":
            return None
        longest = float(graph.neighbor_distances.max(initial=0.0)) * graph.cell_size
        if self.config.sensor_range < longest:
            raise ValueError(
                f"sensor_range {self.config.sensor_range} m is shorter than the longest edge of "
                f"the map ({longest:g} m): robots could move to waypoints they have not sensed"
            )
        return sensor_footprints(graph, self.config.sensor_range)

    def _sense(self) -> None:
        """Exploration: the robots sense around their waypoints; updates the known graph and
        the frontier column of the waypoint features."""
        if self._discovery is None:
            return
        changed = self._discovery.sense(self._robot_node)
        self._waypoint_features[changed, 3] = self._discovery.frontier[changed]

    def step(self, actions: dict[str, Any]) -> StepResult:
        """Moves every robot one step.

        Args:
            actions: One action in ``[0, 5)`` for every live agent.

        Raises:
            RuntimeError: the episode is over (call ``reset``).
            ValueError: an agent is missing or unknown, an action is out of range, or (with
                ``invalid_action="raise"``) an action is masked out; the message names the robot.
        """
        agents = self.agents  # the live agents of this step (apply_actions may end the episode)
        moves = self.apply_actions(self._read_actions(actions))
        infos = self._infos(moves.new_interest, moves.blocked, moves.invalid)
        return self._step_result(
            agents, moves.new_interest, moves.terminated, moves.truncated, infos
        )

    def apply_actions(self, action: np.ndarray) -> Moves:
        """The step's dynamics without the PettingZoo dictionaries (the core that batched
        environments share): resolves ``action`` ``(R,)`` (integers in ``[0, 5)``, already
        checked), moves the robots, marks visits and ends the episode (no live agents) when it
        is over. ``step`` is this plus the observations and dictionaries; after it,
        :meth:`observe_batch` and :meth:`state` give the new observations.
        """
        targets, invalid = self._targets(action)  # (R,), (R,)
        next_node = self._resolve(targets)
        blocked = next_node != targets
        new_interest = self._visit(next_node)  # (R,)
        self._num_steps += 1
        terminated, truncated = self._end_of_step(self._num_steps >= self.config.max_steps)
        return Moves(new_interest, blocked, invalid, terminated, truncated)

    def _resolve(self, targets: np.ndarray) -> np.ndarray:
        """Each robot's next waypoint from its target ``(R,)``: the priority-index resolver,
        compiled where the ego kernels are (the same result)."""
        if self._scratch is not None:
            return resolve_collisions_compiled(
                self._robot_node, targets, self.config.allow_swaps, self._scratch
            )
        return resolve_collisions(self._robot_node, targets, self.config.allow_swaps)

    def _end_of_step(self, out_of_time: bool) -> tuple[bool, bool]:
        """Termination (everything covered) and truncation (``out_of_time`` and not terminated)
        of the step just taken; ends the episode when either holds."""
        terminated = self._all_covered()
        truncated = out_of_time and not terminated
        if terminated or truncated:
            self.agents = []
        return terminated, truncated

    def _step_result(
        self,
        agents: list[str],
        new_interest: np.ndarray,
        terminated: bool,
        truncated: bool,
        infos: dict[str, dict[str, Any]],
    ) -> StepResult:
        """The return of ``step`` for the step's live ``agents``: observations, the team reward,
        termination, truncation and ``infos``."""
        reward = float(new_interest.sum())
        return (
            self.observations(),
            dict.fromkeys(agents, reward),
            dict.fromkeys(agents, terminated),
            dict.fromkeys(agents, truncated),
            infos,
        )

    def _all_covered(self) -> bool:
        """Whether every point of interest has been visited (a count kept step by step)."""
        return self._interest_left == 0

    def _read_actions(self, actions: dict[str, Any]) -> np.ndarray:
        if not self.agents:
            raise RuntimeError("step() called with no live agents; call reset() first")
        return read_actions(actions, self.agents, self.possible_agents)

    def _targets(self, action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Target waypoint of each robot, and which actions were masked out (and become stays)."""
        moves = self._episode_map().neighbors[self._robot_node, np.maximum(action - 1, 0)]
        target = np.where(action == 0, self._robot_node, moves)  # (R,), -1 where masked out
        invalid = target < 0
        if invalid.any() and self.config.invalid_action == "raise":
            i = int(np.flatnonzero(invalid)[0])
            raise ValueError(
                f"action {action[i]} of {self.possible_agents[i]} is masked out: waypoint "
                f"{self._robot_node[i]} has no neighbour that way"
            )
        return np.where(invalid, self._robot_node, target), invalid

    def _visit(self, next_node: np.ndarray) -> np.ndarray:
        """Moves the robots; returns the points of interest each visited first, ``(R,)``."""
        new_interest = self._mark_visited(next_node, distinct=True)
        self._robot_node = next_node
        self._trails.append(next_node.copy())
        self._sense()
        return new_interest

    def _mark_visited(self, node: np.ndarray, distinct: bool = False) -> np.ndarray:
        """Marks ``node`` ``(R,)`` visited (``-1``: robot at no waypoint); returns each robot's
        newly visited points of interest ``(R,)``, credited to the lowest-index robot when two
        reach one at once (``distinct``: the waypoints are distinct, as the resolver's are)."""
        if distinct:
            nodes = node
            fresh = self._interest[nodes] & ~self._visited[nodes]
            new_interest = fresh.astype(np.int64)
        else:
            robots = np.flatnonzero(node >= 0)
            nodes = node[robots]
            fresh = self._interest[nodes] & ~self._visited[nodes]
            if len(nodes) > 1:  # several robots at one waypoint: only the first gets the credit
                first = np.zeros(len(nodes), dtype=bool)
                first[np.unique(nodes, return_index=True)[1]] = True
                fresh &= first
            new_interest = np.zeros(len(node), dtype=np.int64)
            new_interest[robots] = fresh
        self._interest_left -= int(np.count_nonzero(fresh))
        self._visited[nodes] = True
        self._waypoint_features[nodes, 2] = 0.0
        self._credits += new_interest
        return new_interest

    @property
    def credits(self) -> np.ndarray:
        """Points of interest each robot has visited first this episode, ``(R,)`` (a copy)."""
        return self._credits.copy()

    def _infos(
        self, new_interest: np.ndarray, blocked: np.ndarray, invalid: np.ndarray
    ) -> dict[str, dict[str, Any]]:
        columns = (
            new_interest.tolist(),
            self._credits.tolist(),
            blocked.tolist(),
            invalid.tolist(),
        )
        return {
            agent: {
                "new_interest": new,
                "total_interest": total,
                "blocked": stopped,
                "invalid_action": masked,
            }
            for agent, new, total, stopped, masked in zip(
                self.possible_agents, *columns, strict=True
            )
        }

    def state(self) -> dict[str, np.ndarray]:
        """The whole graph in the observation encoding (see the module docstring)."""
        self._episode_map()
        return self._build_state(*self._view(), self._discovery)

    def _build_state(
        self, robot_node: np.ndarray, features: np.ndarray, discovery: Discovery | None
    ) -> dict[str, np.ndarray]:
        """The state of robots on ``robot_node`` ``(R,)`` with waypoint ``features`` ``(N, 4)``
        (only what ``discovery`` holds, or every waypoint), with the clock."""
        assert self._state_builder is not None  # built with the map
        state = self._state_builder.build(robot_node, features, discovery)
        state["steps_left"] = np.array(self._steps_left(), dtype=np.int64)
        return state

    def _view(self) -> tuple[np.ndarray, np.ndarray]:
        """What the observations and ``state()`` are built on: each robot's waypoint ``(R,)``
        and the waypoint features ``(N, 4)``."""
        return self._robot_node, self._waypoint_features

    def _steps_left(self) -> int:
        """Actions left in the episode (``state()["steps_left"]``)."""
        return self.config.max_steps - self._num_steps

    def fork(self) -> CoverageEnv:
        """An independent copy of the environment mid-episode, for planners that play futures
        out: the episode's state (positions, visits, clock, generator, discovery) is copied;
        what no step changes (the configuration, the map, the spaces, the state builder) is
        shared, which makes a fork several times cheaper than a plain ``copy.deepcopy`` (the
        kernels' search tables too: step one environment's forks one at a time, never in
        threads). A fork draws with a renderer of its own, made on its first ``render()``."""
        shared = map(self.__dict__.get, self._FORK_SHARED)
        memo: dict[int, Any] = {id(part): part for part in shared if part is not None}
        if self._renderer is not None:
            memo[id(self._renderer)] = None
        return copy.deepcopy(self, memo)

    def snapshot(self) -> CoverageSnapshot:
        """A read-only copy of the episode's state for planners."""
        return CoverageSnapshot(
            graph=self._episode_map(),
            robot_node=self._robot_node.copy(),
            interest=self._interest.copy(),
            visited=self._visited.copy(),
            num_steps=self._num_steps,
            max_steps=self.config.max_steps,
            hops=self.config.hops,
            discovered=self._discovered(),
        )

    def _discovered(self) -> np.ndarray:
        """Waypoints known to the team, ``(N,)`` bool (a copy; all of them in coverage)."""
        if self._discovery is None:
            return np.ones(self._episode_map().num_nodes, dtype=bool)
        return self._discovery.discovered.copy()

    def _episode_map(self) -> SpatialGraph:
        """This episode's map.

        Raises:
            RuntimeError: no episode has started (``reset()`` was not called yet).
        """
        if self._graph is None:
            raise RuntimeError("no episode yet; call reset() first")
        return self._graph


def _config_kwargs(kwargs: dict[str, Any]) -> dict[str, Any]:
    """Maps PettingZoo's ``max_cycles`` to ``max_steps``."""
    if "max_cycles" in kwargs:
        if "max_steps" in kwargs:
            raise TypeError("give max_steps or max_cycles, not both")
        kwargs = dict(kwargs)
        kwargs["max_steps"] = kwargs.pop("max_cycles")
    return kwargs


def parallel_env(config: CoverageConfig | None = None, **kwargs: Any) -> CoverageEnv:
    """The coverage environment as a PettingZoo ``ParallelEnv``.

    Args:
        config: A full :class:`CoverageConfig`; keyword arguments override its fields.
        **kwargs: Fields of :class:`CoverageConfig` (``max_cycles`` = ``max_steps``).
    """
    return CoverageEnv(config, **_config_kwargs(kwargs))


def env(config: CoverageConfig | None = None, **kwargs: Any):  # noqa: ANN201 (PettingZoo type)
    """The coverage environment as a PettingZoo AEC env (``parallel_to_aec``)."""
    return parallel_to_aec(parallel_env(config, **kwargs))
