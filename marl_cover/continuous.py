"""Coverage with robots that have dynamics: quadrotor-like bodies in continuous time.

The same task, observations and agents as :class:`marl_cover.env.CoverageEnv`, but each robot
is a body (:mod:`marl_cover.dynamics`) that flies to the waypoint it is given:

- **Positions to waypoints.** A robot's measured position is snapped to the nearest waypoint
  (Euclidean, in the plane); the observations and ``state()`` are built on the snapped
  waypoints, in the discrete environment's encoding, so discrete policies drive the bodies
  unchanged. An action is a move from the snapped waypoint. With ``observe="targets"`` the
  robots that are on their way appear at their target waypoints instead, those counted as
  visited (the pending moves completed; the reward and the record of visits are unchanged).
- **Targets.** Each robot holds a target waypoint that its position controller tracks at its
  own altitude. Targets are pairwise distinct: new targets go through the priority-index
  collision resolver (:mod:`marl_cover.collisions`) against the current targets, and a blocked
  robot keeps its target.
- **When robots decide.** ``retarget="arrival"``: a robot takes a new target when it is within
  ``arrival_radius`` of its current one; a step lasts until at least one robot is ready (whole
  control periods), and only the ready robots' actions are used (``infos[agent]["ready"]``
  says which). ``retarget="rate"``: every robot takes a new target every ``control_period``
  (the paper's 10 Hz loop; a robot is sent on toward a neighbour of the waypoint it is nearest
  to, so it need not stop at waypoints).
- **Visiting.** A waypoint is visited when a robot's true position comes within
  ``visit_radius`` of it in the plane (checked every integration step); reward is +1 per point
  of interest newly visited, for the whole team, as in coverage. The default radius, half the
  lattice spacing, is the paper's rule (the waypoint a robot is snapped to is visited), and it
  keeps the observations in the discrete encoding: a robot's own waypoint is always visited.
  With a smaller radius, a robot between waypoints can be snapped to one it has not visited
  yet, which discrete policies never saw; fly them in ``"arrival"`` mode then.
- **Safety.** Robots fly at fixed, distinct altitudes (``altitude_range``). A near-miss is two
  robots closer than ``safety_distance`` in the plane and within ``same_altitude`` in height;
  the count of such encounters is in ``infos[agent]["near_misses"]``.
- **Time.** The episode is truncated after ``max_time`` seconds (``CoverageConfig.max_steps``
  is not used); ``infos[agent]["time"]`` is the mission time, and ``state()["steps_left"]``
  and each observation's ``steps_left`` count the nominal moves left
  (:meth:`QuadrotorCoverageEnv.snapshot`).

With infinite speed and acceleration (:meth:`QuadrotorParams.ideal`) every move takes one
integration step and this environment reproduces the discrete one step for step (tested).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import gymnasium
import numpy as np

from marl_cover.collisions import resolve_collisions
from marl_cover.config import CoverageConfig, check_field_types, config_from_dict, require
from marl_cover.dynamics import (
    DYNAMICS_BACKENDS,
    QuadrotorParams,
    QuadrotorTeam,
    compiled_kernels,
)
from marl_cover.ego import action_targets
from marl_cover.env import CoverageEnv, StepResult, _config_kwargs
from marl_cover.graph import SpatialGraph
from marl_cover.locator import WaypointLocator

RETARGET_MODES = ("arrival", "rate")
OBSERVE_MODES = ("snapped", "targets")


@dataclass(frozen=True)
class DynamicsConfig:
    """Configuration of the continuous-time mode (SI units).

    Attributes:
        quadrotor: Body and controller parameters (a dict of them is accepted).
        retarget: ``"arrival"`` (new target on reaching the current one) or ``"rate"`` (every
            robot every ``control_period``).
        control_period: Period of the control loop in seconds (the paper's 10 Hz: 0.1); a
            whole number of integration steps.
        max_time: Mission length in seconds.
        visit_radius: A waypoint is visited by a robot within this distance, metres
            (``None``: half the map's cell size).
        arrival_radius: A robot has reached its target within this distance, metres.
        altitude_range: Altitudes of the robots, evenly spaced from the first to the second
            (metres; the paper's ``linspace(3, 8, R)``).
        safety_distance: Near-miss distance in the plane, metres.
        same_altitude: Two robots within this height difference share an altitude, metres.
        noise_std: Standard deviation of the position measurement noise, metres.
        delay: Actuation delay in seconds.
        backend: How the bodies are integrated, waypoints looked up and near-misses counted:
            ``"numpy"`` (the reference), ``"numba"`` (compiled kernels, the same bits) or
            ``"auto"`` (``"numba"`` when installed).
        observe: Where the observations put the robots that are on their way:
            ``"snapped"`` (the waypoint nearest to each, the paper's rule) or ``"targets"``
            (the waypoint each is bound to, counted as visited: the pending moves completed,
            as the discrete environment shows robots after a step). Robots that are ready
            are at their snapped waypoints in both.
    """

    quadrotor: QuadrotorParams = field(default_factory=QuadrotorParams)
    retarget: str = "arrival"
    control_period: float = 0.1
    max_time: float = 400.0
    visit_radius: float | None = None
    arrival_radius: float = 0.5
    altitude_range: tuple[float, float] = (3.0, 8.0)
    safety_distance: float = 1.0
    same_altitude: float = 0.5
    noise_std: float = 0.0
    delay: float = 0.0
    backend: str = "auto"
    observe: str = "snapped"

    def __post_init__(self) -> None:
        if isinstance(self.quadrotor, dict):
            object.__setattr__(self, "quadrotor", config_from_dict(QuadrotorParams, self.quadrotor))
        check_field_types(self)
        object.__setattr__(self, "altitude_range", tuple(float(a) for a in self.altitude_range))
        substeps = self.control_period / self.quadrotor.dt
        checks = [
            (self.retarget in RETARGET_MODES, f"retarget must be one of {RETARGET_MODES}"),
            (
                self.control_period > 0 and abs(substeps - round(substeps)) < 1e-9,
                f"control_period ({self.control_period}) must be a positive multiple of "
                f"quadrotor.dt ({self.quadrotor.dt})",
            ),
            (self.max_time > 0, f"max_time must be > 0, got {self.max_time}"),
            (self.arrival_radius > 0, f"arrival_radius must be > 0, got {self.arrival_radius}"),
            (
                self.visit_radius is None or self.visit_radius >= self.arrival_radius,
                "need visit_radius >= arrival_radius (a reached target is visited)",
            ),
            (len(self.altitude_range) == 2, "altitude_range must be (low, high)"),
            (self.safety_distance >= 0, "safety_distance must be >= 0"),
            (self.same_altitude >= 0, "same_altitude must be >= 0"),
            (self.noise_std >= 0, f"noise_std must be >= 0, got {self.noise_std}"),
            (self.delay >= 0, f"delay must be >= 0, got {self.delay}"),
            (self.backend in DYNAMICS_BACKENDS, f"backend must be one of {DYNAMICS_BACKENDS}"),
            (self.observe in OBSERVE_MODES, f"observe must be one of {OBSERVE_MODES}"),
        ]
        require(*checks, prefix="DynamicsConfig: ")

    @property
    def substeps(self) -> int:
        """Integration steps per control period."""
        return round(self.control_period / self.quadrotor.dt)

    @property
    def max_ticks(self) -> int:
        """Integration steps in a mission."""
        return math.ceil(self.max_time / self.quadrotor.dt - 1e-9)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> DynamicsConfig:
        """Builds the config; unknown keys are errors (also inside ``quadrotor``)."""
        return config_from_dict(cls, values)


class QuadrotorCoverageEnv(CoverageEnv):
    """Coverage with quadrotor-like robots in continuous time; see the module docstring.

    Args:
        config: Task configuration (map, robots, points of interest, hops, ...).
        dynamics: A :class:`DynamicsConfig` or a dict of its fields.
        **overrides: Fields of :class:`CoverageConfig`.
    """

    metadata = {**CoverageEnv.metadata, "name": "marl_cover_quadrotor_v0"}
    #: Robots in flight are shown on their nearest waypoint, which two can share.
    _DISTINCT_VIEW = False

    #: The dynamics, its compiled kernels and the waypoint lookup never change in an episode.
    _FORK_SHARED = (*CoverageEnv._FORK_SHARED, "dynamics", "_kernels", "_locator")

    def __init__(
        self,
        config: CoverageConfig | None = None,
        dynamics: DynamicsConfig | dict[str, Any] | None = None,
        **overrides: Any,
    ) -> None:
        super().__init__(config, **overrides)
        if self.config.task != "coverage":
            raise ValueError(
                f"the quadrotor simulation runs task='coverage' only, got {self.config.task!r}"
            )
        if isinstance(dynamics, dict):
            dynamics = DynamicsConfig.from_dict(dynamics)
        if not isinstance(dynamics, DynamicsConfig | None):
            raise TypeError(
                f"dynamics must be a DynamicsConfig or a dict of its fields, got {dynamics!r}"
            )
        self.dynamics = dynamics or DynamicsConfig()
        self._kernels = compiled_kernels(self.dynamics.backend)  # None: numpy
        self._locator: WaypointLocator | None = None
        self._tick = 0  # integration steps of the mission (the clock)
        # nominal moves (see snapshot) are at least a control period long
        most = math.ceil(self.dynamics.max_time / self.dynamics.control_period)
        clock = gymnasium.spaces.Box(0, most, (), np.int64)
        self.state_space["steps_left"] = self._observation_space["steps_left"] = clock

    # ------------------------------------------------------------------ public state
    @property
    def time(self) -> float:
        """Mission time in seconds."""
        return self._tick * self.dynamics.quadrotor.dt

    @property
    def positions(self) -> np.ndarray:
        """True positions ``(R, 3)`` in metres (a copy)."""
        return self._team.position.copy()

    @property
    def targets(self) -> np.ndarray:
        """Target waypoint of each robot ``(R,)`` (a copy)."""
        return self._target.copy()

    @property
    def ready(self) -> np.ndarray:
        """Which robots take a new target at the next step ``(R,)`` (a copy)."""
        return self._ready.copy()

    @property
    def snapped(self) -> np.ndarray:
        """Waypoint nearest to each robot's measured position ``(R,)``: the one its
        observation is built on and its moves start from (a copy)."""
        return self._robot_node.copy()

    @property
    def observed_nodes(self) -> np.ndarray:
        """Waypoint each robot is at in the observations and ``state()`` ``(R,)``: its snapped
        waypoint, or its target while on its way with ``observe="targets"`` (a copy)."""
        return np.where(self._shown_at_target(), self._target, self._robot_node)

    @property
    def num_visited(self) -> int:
        """Waypoints visited so far."""
        return int(self._visited.sum())

    @property
    def arrived(self) -> np.ndarray:
        """Which robots are within ``arrival_radius`` of their target ``(R,)`` (a copy)."""
        return self._arrived.copy()

    @property
    def seconds_per_hop(self) -> float:
        """Nominal time of one move: an edge at full speed, plus the time to reach that speed
        and to brake from it when robots stop at waypoints (``"arrival"``); at least one
        control period."""
        q = self.dynamics.quadrotor
        cruise = self._episode_map().cell_size / q.max_speed
        if self.dynamics.retarget == "arrival" and not math.isinf(q.max_accel):
            cruise += q.max_speed / q.max_accel
        return max(cruise, self.dynamics.control_period)

    @property
    def near_misses(self) -> int:
        """Near-miss encounters so far in the episode."""
        return self._near_misses

    # ------------------------------------------------------------------ episode
    def _check_map(self, graph: SpatialGraph) -> None:
        """The default ``visit_radius`` (half the cell size) must cover the arrival radius."""
        super()._check_map(graph)
        d = self.dynamics
        if d.visit_radius is None and 0.5 * graph.cell_size < d.arrival_radius:
            raise ValueError(
                f"arrival_radius {d.arrival_radius} m exceeds half the map's cell size "
                f"({0.5 * graph.cell_size} m), the default visit_radius"
            )

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, dict[str, Any]]]:
        """Starts a mission: the discrete reset, then robots hovering over their start
        waypoints at their altitudes. ``seed`` and ``options`` as in :meth:`CoverageEnv.reset`."""
        self._start_episode(seed, options)
        graph, d = self._episode_map(), self.dynamics
        self._visit_radius = d.visit_radius
        if self._visit_radius is None:
            self._visit_radius = 0.5 * graph.cell_size
        r = self.config.num_robots
        self._altitude = np.linspace(*d.altitude_range, r)  # (R,)
        start = np.column_stack([graph.positions[self._robot_node], self._altitude])
        self._team = QuadrotorTeam(
            d.quadrotor, start, d.noise_std, d.delay, self._rng, backend=d.backend
        )
        self._target = self._robot_node.copy()
        self._tick = 0
        self._near_misses = 0
        self._close_pairs = np.zeros((r, r), dtype=bool)
        self._ready = np.ones(r, dtype=bool)
        self._arrived = np.ones(r, dtype=bool)
        zeros = np.zeros(r, dtype=np.int64)
        infos = self._continuous_infos(zeros, zeros.astype(bool), zeros.astype(bool))
        return self.observations(), infos

    def step(self, actions: dict[str, Any]) -> StepResult:
        """Applies the ready robots' actions, then flies until a robot is ready again
        (``"arrival"``) or for one control period (``"rate"``).

        Args:
            actions: One action in ``[0, 5)`` for every live agent (those of robots that are
                not ready are checked and ignored).

        Raises:
            RuntimeError: the episode is over.
            ValueError: as :meth:`CoverageEnv.step`.
        """
        agents = self.agents
        action = self._read_actions(actions)  # (R,)
        proposed, invalid = self._propose(action)  # (R,), (R,)
        self._target = resolve_collisions(self._target, proposed, self.config.allow_swaps)
        blocked = self._target != proposed
        new_interest = self._fly()  # (R,)
        self._num_steps += 1
        self._trails.append(self._robot_node.copy())
        infos = self._continuous_infos(new_interest, blocked, invalid)
        terminated, truncated = self._end_of_step(self._tick >= self.dynamics.max_ticks)
        return self._step_result(agents, new_interest, terminated, truncated, infos)

    def _propose(self, action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Targets the ready robots ask for (from their snapped waypoints); others keep theirs."""
        slots = action_targets(self._episode_map(), self._robot_node)  # (R, 5)
        wanted = slots[np.arange(len(action)), action]
        invalid = (wanted < 0) & self._ready
        if invalid.any() and self.config.invalid_action == "raise":
            i = int(np.flatnonzero(invalid)[0])
            raise ValueError(
                f"action {action[i]} of {self.possible_agents[i]} is masked out: waypoint "
                f"{self._robot_node[i]} has no neighbour that way"
            )
        wanted = np.where(wanted < 0, self._robot_node, wanted)
        return np.where(self._ready, wanted, self._target), invalid

    def _fly(self) -> np.ndarray:
        """Integrates whole control periods; returns each robot's new points of interest."""
        d = self.dynamics
        positions = self._episode_map().positions  # (N, 2)
        goal = np.column_stack([positions[self._target], self._altitude])  # (R, 3)
        new_interest = np.zeros(self.config.num_robots, dtype=np.int64)
        r = self.config.num_robots
        track = np.empty((d.substeps, r, 3))  # positions at each integration step
        while True:
            self._team.advance(goal, d.substeps, track)
            self._tick += d.substeps
            # Visits, checked at every integration step (one lookup for the whole period).
            near, dist = self._nearest(track.reshape(-1, 3))
            near, dist = near.reshape(d.substeps, r), dist.reshape(d.substeps, r)
            reached = (dist <= self._visit_radius) & ~self._visited[near]
            for k in np.flatnonzero(reached.any(axis=1)):  # in time order, for the credits
                new_interest += self._mark_visited(np.where(reached[k], near[k], -1))
            self._count_near_misses()
            measured = self._team.measure()
            self._robot_node, _ = self._nearest(measured)
            offset = measured[:, :2] - positions[self._target]
            self._arrived = np.einsum("ij,ij->i", offset, offset) <= d.arrival_radius**2
            self._ready = self._arrived if d.retarget == "arrival" else np.ones_like(self._ready)
            done = self._tick >= d.max_ticks or self._all_covered()
            if self._ready.any() or done:
                return new_interest

    def _nearest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest waypoint ``(R,)`` and its distance in the plane ``(R,)``."""
        graph = self._episode_map()
        if self._locator is None or self._locator.graph is not graph:
            self._locator = WaypointLocator(graph, self.dynamics.backend)
        return self._locator.nearest(points)

    def _count_near_misses(self) -> None:
        """Counts pairs that came within the safety distance at one altitude (once per
        encounter)."""
        d = self.dynamics
        p = self._team.position
        if self._kernels is not None:
            self._near_misses += self._kernels.count_new_close_pairs(
                p, d.safety_distance, d.same_altitude, self._close_pairs
            )
            return
        planar = np.linalg.norm(p[:, None, :2] - p[None, :, :2], axis=-1)
        vertical = np.abs(p[:, None, 2] - p[None, :, 2])
        close = (planar < d.safety_distance) & (vertical < d.same_altitude)
        np.fill_diagonal(close, False)
        self._near_misses += int(np.triu(close & ~self._close_pairs).sum())
        self._close_pairs = close

    def _continuous_infos(
        self, new_interest: np.ndarray, blocked: np.ndarray, invalid: np.ndarray
    ) -> dict[str, dict[str, Any]]:
        infos = self._infos(new_interest, blocked, invalid)
        for i, info in enumerate(infos.values()):
            info.update(
                time=self.time,
                ready=bool(self._ready[i]),
                target=int(self._target[i]),
                position=self._team.position[i].copy(),
                near_misses=self._near_misses,
            )
        return infos

    def _progress_text(self) -> str:
        return f"t = {self.time:.1f}/{self.dynamics.max_time:.0f} s"

    def _robot_xy(self) -> np.ndarray:
        return self._team.position[:, :2]

    def snapshot(self):  # noqa: ANN201 (CoverageSnapshot)
        """The discrete snapshot for planners, with each robot at its target waypoint (where
        it is bound) and time counted in nominal moves (:attr:`seconds_per_hop`): ``num_steps``
        moves done, ``max_steps`` in the mission."""
        num_steps, max_steps = self._nominal_steps()
        return dataclasses.replace(
            super().snapshot(),
            robot_node=self._target.copy(),
            num_steps=num_steps,
            max_steps=max_steps,
        )

    def _nominal_steps(self) -> tuple[int, int]:
        """Moves done and moves in the mission, counted in :attr:`seconds_per_hop`."""
        hop = self.seconds_per_hop
        done = math.floor(self.time / hop + 1e-9)
        return done, math.ceil(self.dynamics.max_time / hop - 1e-9)

    def _shown_at_target(self) -> np.ndarray:
        """Robots the observations place at their targets ``(R,)``: those on their way, with
        ``observe="targets"``."""
        return ~self._ready & (self.dynamics.observe == "targets")

    def _view(self) -> tuple[np.ndarray, np.ndarray]:
        """Robots on their way at their targets, those targets visited (``observe="targets"``)."""
        pending = self._shown_at_target()  # (R,)
        if not pending.any():
            return super()._view()
        features = self._waypoint_features.copy()
        features[self._target[pending], 2] = 0.0
        return np.where(pending, self._target, self._robot_node), features

    def _steps_left(self) -> int:
        """Nominal moves left in the mission (``state()["steps_left"]``)."""
        done, total = self._nominal_steps()
        return max(total - done, 0)


def parallel_env(
    config: CoverageConfig | None = None,
    dynamics: DynamicsConfig | dict[str, Any] | None = None,
    **kwargs: Any,
) -> QuadrotorCoverageEnv:
    """The quadrotor coverage environment as a PettingZoo ``ParallelEnv``.

    Args:
        config: A full :class:`CoverageConfig`; keyword arguments override its fields.
        dynamics: A :class:`DynamicsConfig` or a dict of its fields.
        **kwargs: Fields of :class:`CoverageConfig`.
    """
    return QuadrotorCoverageEnv(config, dynamics, **_config_kwargs(kwargs))


def env(config=None, dynamics=None, **kwargs: Any):  # noqa: ANN001, ANN201 (PettingZoo type)
    """The quadrotor coverage environment as a PettingZoo AEC env (``parallel_to_aec``)."""
    from pettingzoo.utils.conversions import parallel_to_aec

    return parallel_to_aec(parallel_env(config, dynamics, **kwargs))
