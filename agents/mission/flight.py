"""Missions: discrete policies flying quadrotor-like robots (:mod:`marl_cover.continuous`).

The policies are the discrete ones, unchanged. At each step of the environment the runner asks
for actions only when some robot is ready, and hands the environment every robot's action
(those of robots that are not ready are ignored there):

- a policy with ``act_state`` (centralized GNN, centralized greedy) sees ``env.state()``;
- a policy with ``act`` (decentralized GNN, greedy) sees the ready robots' observations only;
- the routing expert plans on the target waypoints through :class:`MissionExpert`.

Deterministic observation-only policies are not asked again while nothing they observe has
changed (same observed waypoints, same visited set, same ready robots): at 10 Hz most control
periods change nothing, and the actions would be the same.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from marl_cover.agents.experts.expert import RoutingExpert, step_toward
from marl_cover.agents.io import file_sha256
from marl_cover.continuous import DynamicsConfig, QuadrotorCoverageEnv


class MissionExpert:
    """The routing expert flying bodies: it plans on the target waypoints.

    A robot that has arrived at its target takes the next hop of its route (the expert's
    open-loop plan, redone when a robot is blocked or a route runs out); a robot still on its
    way keeps its target. Moves are expressed from each robot's snapped waypoint, which is its
    target once it has arrived.

    Args:
        expert: The routing expert (its ``mode`` and solver settings are used as they are).
    """

    def __init__(self, expert: RoutingExpert) -> None:
        self.expert = expert

    @property
    def counts(self) -> Any:
        """The expert's solve, re-plan and fallback counters."""
        return self.expert.counts

    def reset(self, seed: int | None = None) -> None:
        """Forgets the plan."""
        self.expert.reset(seed)

    def act_env(self, env: QuadrotorCoverageEnv) -> dict[str, int]:
        """Every robot's action (those of robots that are not ready are ignored by the env)."""
        snapshot = env.snapshot()  # robots at their targets
        arrived = env.arrived
        actions = self.expert.act_snapshot(snapshot, active=arrived)
        graph, target = snapshot.graph, snapshot.robot_node
        moved = graph.neighbors[target, (actions - 1).clip(min=0)]
        wanted = np.where((actions > 0) & arrived, moved, target)  # (R,)
        moves = _moves(graph, env.snapped, wanted)
        return dict(zip(env.possible_agents, moves.tolist(), strict=True))


def _moves(graph: Any, node: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """Action from ``node`` toward ``wanted`` (a neighbour, itself, or farther away)."""
    actions = np.zeros(len(node), dtype=np.int64)
    for slot in range(4):
        actions[graph.neighbors[node, slot] == wanted] = slot + 1
    far = np.flatnonzero((actions == 0) & (wanted != node))
    if len(far):
        actions[far] = step_toward(graph, node[far], wanted[far])
    return actions


@dataclass(frozen=True)
class MissionResult:
    """One mission.

    Attributes:
        seed: Episode seed.
        visited: Points of interest visited by each whole second, ``(floor(max_time) + 1,)``.
        total: Points of interest visited in the mission.
        num_interest: Points of interest of the mission.
        near_misses: Near-miss encounters.
        decisions: Steps at which the policy was asked.
        steps: Environment steps.
        mission_seconds: Simulated time.
        wall_seconds: Wall time of the whole mission, policy included.
        policy_seconds: Wall time inside the policy.
        frames: Recorded ``(time, positions (R, 3), visited (N,))`` when asked, else empty.
    """

    seed: int
    visited: list[int]
    total: int
    num_interest: int
    near_misses: int
    decisions: int
    steps: int
    mission_seconds: float
    wall_seconds: float
    policy_seconds: float
    policy_counts: dict[str, int] = field(default_factory=dict)
    frames: list[tuple[float, np.ndarray, np.ndarray]] = field(default_factory=list, repr=False)

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall second."""
        return self.mission_seconds / max(self.wall_seconds, 1e-12)

    def as_dict(self) -> dict[str, Any]:
        """Plain types, for JSON (without frames)."""
        out = asdict(self)
        out.pop("frames")
        out["real_time_factor"] = self.real_time_factor
        return out


def ask_policy(
    policy: Any, env: QuadrotorCoverageEnv, observations: dict[str, Any]
) -> dict[str, int]:
    """Every robot's action from ``policy`` (see the module docstring); the actions of robots
    that are not ready are ignored by the environment."""
    if hasattr(policy, "act_env"):
        return policy.act_env(env)
    if hasattr(policy, "act_state"):
        actions = np.asarray(policy.act_state(env.state()))
        return dict(zip(env.possible_agents, actions.tolist(), strict=True))
    ready = [a for a, r in zip(env.possible_agents, env.ready, strict=True) if r]
    chosen = policy.act({a: observations[a] for a in ready})
    return {a: int(chosen.get(a, 0)) for a in env.possible_agents}


def run_mission(
    env: QuadrotorCoverageEnv,
    policy: Any,
    seed: int,
    record_every: float | None = None,
) -> MissionResult:
    """Flies one mission with ``policy``.

    Args:
        env: The quadrotor environment (its configuration fixes the mission).
        policy: A discrete policy (see the module docstring) or a :class:`MissionExpert`.
        seed: Episode seed (paired across policies).
        record_every: Record positions and visits every this many mission seconds.
    """
    start = time.perf_counter()
    if hasattr(policy, "reset"):
        policy.reset(seed)
    observations, _ = env.reset(seed=seed)
    cacheable = not hasattr(policy, "act_env") and getattr(policy, "deterministic", True)
    interest = env.snapshot().interest
    seconds = int(np.floor(env.dynamics.max_time))
    visited_at = np.zeros(seconds + 1, dtype=np.int64)
    frames: list[tuple[float, np.ndarray, np.ndarray]] = []
    next_frame = 0.0
    policy_seconds, decisions, steps, total = 0.0, 0, 0, 0
    key: tuple[Any, ...] | None = None
    actions: dict[str, int] = {}
    while env.agents:
        snap_key = (
            env.observed_nodes.tobytes(),
            env.num_visited,
            env.ready.tobytes(),
        )
        if not cacheable or snap_key != key:
            tick = time.perf_counter()
            actions = ask_policy(policy, env, observations)
            policy_seconds += time.perf_counter() - tick
            decisions += 1
            key = snap_key
        before = env.time
        observations, rewards, *_ = env.step(actions)
        steps += 1
        total += int(next(iter(rewards.values())))
        visited_at[int(np.floor(before)) + 1 : int(np.floor(env.time)) + 1] = total
        if record_every is not None and env.time >= next_frame:
            frames.append((env.time, env.positions, env.snapshot().visited & interest))
            next_frame += record_every
    visited_at[int(np.floor(env.time)) + 1 :] = total
    return MissionResult(
        seed=seed,
        visited=visited_at.tolist(),
        total=total,
        num_interest=int(interest.sum()),
        near_misses=env.near_misses,
        decisions=decisions,
        steps=steps,
        mission_seconds=env.time,
        wall_seconds=time.perf_counter() - start,
        policy_seconds=policy_seconds,
        policy_counts=dict(getattr(policy, "counts", {})),
        frames=frames,
    )


@dataclass
class MissionConfig:
    """The quadrotor mission (defaults: the paper's, the paper's).

    Attributes:
        map: Map preset or grid file (the paper's 1266-waypoint graph).
        num_robots: Team size.
        interest_fraction: Fraction of the waypoints that are points of interest.
        hops: Receptive field of greedy (the GNN uses its own: the ego-graphs span the larger
            of the two).
        methods: Any of ``"greedy"`` (the paper's: a random move when nothing is within
            ``hops``), ``"greedy_stay"`` (stays instead), ``"gnn"``, ``"expert"``.
        seeds: Missions per method (seeds ``seed .. seed + seeds - 1``, paired).
        seed: First seed.
        model: The GNN flown: a shipped model name or a model file (``gnn_mission``, the
            29-hop model made for the mission).
        gnn_centralized: One pass over ``state()`` instead of the ready robots' ego-graphs.
        gnn_spread: Break the GNN's near-ties toward the move that leads away from teammates
            (``GNNPolicy(spread_margin=...)``, :mod:`marl_cover.agents.baselines.spread`; ego-graphs
            only); ``None``: the plain argmax.
        gnn_rollout: Play the GNN's near-tied moves (within this margin of the best logit) out
            on each ready robot's ego-graph and take the best
            (:mod:`marl_cover.agents.planners.local_rollout`, a decentralized planner on top of the
            GNN); ``None``: off.
        gnn_rollout_horizon: Moves of each such play-out (the world is the discrete
            environment on the robot's ego-graph).
        gnn_rollout_greedy_after: Greedy plays each play-out's moves after this many of the
            network's (``LocalRolloutPolicy(greedy_after=...)``: several times faster);
            ``None``: the network to the end.
        expert_iterations: PyVRP iterations per expert solve (deterministic plans).
        dynamics: The continuous-time mode (quadrotor, control loop, radii, altitudes, noise).
        out: Output folder.
        animate_seed: Seed whose GNN mission is animated (``None``, or ``null`` in YAML: no
            animation).
        frame_every: Mission seconds between animation frames.
    """

    map: str = "paper_full"
    num_robots: int = 10
    interest_fraction: float = 0.5
    hops: int = 19
    methods: list[str] = field(default_factory=lambda: ["greedy", "gnn", "expert"])
    seeds: int = 10
    seed: int = 0
    model: str = "gnn_mission"
    gnn_centralized: bool = False
    gnn_spread: float | None = None
    gnn_rollout: float | None = None
    gnn_rollout_horizon: int = 20
    gnn_rollout_greedy_after: int | None = None
    expert_iterations: int = 2000
    dynamics: DynamicsConfig = field(default_factory=DynamicsConfig)
    out: str = "outputs/mission"
    animate_seed: int | None = 0
    frame_every: float = 2.0

    def __post_init__(self) -> None:
        unknown = sorted(set(self.methods) - set(MISSION_METHODS))
        if unknown:
            raise ValueError(f"unknown mission method(s) {unknown}; choose from {MISSION_METHODS}")
        for name, value, smallest in (
            ("num_robots", self.num_robots, 1),
            ("seeds", self.seeds, 1),
            ("seed", self.seed, 0),
            ("animate_seed", 0 if self.animate_seed is None else self.animate_seed, 0),
        ):
            if value < smallest:
                raise ValueError(f"mission {name} must be >= {smallest}, got {value}")
        if self.frame_every <= 0:
            raise ValueError(f"mission frame_every must be > 0 seconds, got {self.frame_every}")
        if isinstance(self.dynamics, dict):
            self.dynamics = DynamicsConfig.from_dict(self.dynamics)
        if self.gnn_spread is not None and (self.gnn_centralized or not self.gnn_spread >= 0):
            raise ValueError(
                f"mission gnn_spread must be >= 0 and needs gnn_centralized=false, got "
                f"gnn_spread={self.gnn_spread} gnn_centralized={self.gnn_centralized}"
            )
        if self.gnn_rollout is not None and (
            self.gnn_centralized
            or self.gnn_spread is not None
            or not self.gnn_rollout >= 0
            or self.gnn_rollout_horizon < 1
            or (self.gnn_rollout_greedy_after or 0) < 0
        ):
            raise ValueError(
                f"mission gnn_rollout must be >= 0 with gnn_rollout_horizon >= 1 and "
                f"gnn_rollout_greedy_after >= 0 (or null), on ego-graphs and without gnn_spread; "
                f"got gnn_rollout={self.gnn_rollout} "
                f"gnn_rollout_horizon={self.gnn_rollout_horizon} "
                f"gnn_rollout_greedy_after={self.gnn_rollout_greedy_after} "
                f"gnn_centralized={self.gnn_centralized} gnn_spread={self.gnn_spread}"
            )
        if "gnn" in self.methods:
            self.gnn_model_path()  # names a model that is neither shipped nor a file

    def make_env(self) -> QuadrotorCoverageEnv:
        """The mission's environment; its ego-graphs span :meth:`observation_hops`."""
        return QuadrotorCoverageEnv(
            map=self.map,
            num_robots=self.num_robots,
            interest_fraction=self.interest_fraction,
            hops=self.observation_hops(),
            dynamics=self.dynamics,
        )

    def observation_hops(self) -> int:
        """Radius of the ego-graphs: ``hops``, or the GNN's receptive field where it flies on
        ego-graphs and sees farther (a larger ego-graph changes nothing for greedy, which
        counts only the points within its ``hops``)."""
        if "gnn" not in self.methods or self.gnn_centralized:
            return self.hops
        from marl_cover.agents.models.checkpoints import load_model

        model, _ = load_model(self.gnn_model_path())
        return max(self.hops, model.config.hops)

    def gnn_model_path(self) -> Path:
        """The GNN model file flown (``model``: a shipped name or a file).

        Raises:
            FileNotFoundError: ``model`` is neither, naming the shipped models.
        """
        from marl_cover.agents.models.shipped import model_path

        return model_path(self.model)

    def setup(self, method: str) -> dict[str, Any]:
        """What decides ``method``'s missions besides the seed (kept beside each run's result).

        The GNN's model enters as the SHA-256 of its file, so that a run flown with another
        model (another file under the same shipped name included) is told apart.
        """
        setup = {
            "method": method,
            "map": self.map,
            "num_robots": self.num_robots,
            "interest_fraction": self.interest_fraction,
            "dynamics": asdict(self.dynamics),
        }
        if method.startswith("greedy"):
            setup["hops"] = self.hops
        elif method == "gnn":
            setup["model_sha256"] = file_sha256(self.gnn_model_path())
            setup["gnn_centralized"] = self.gnn_centralized
            if self.gnn_spread is not None:  # absent from setups recorded before it existed
                setup["gnn_spread"] = self.gnn_spread
            if self.gnn_rollout is not None:
                setup["gnn_rollout"] = self.gnn_rollout
                setup["gnn_rollout_horizon"] = self.gnn_rollout_horizon
                if self.gnn_rollout_greedy_after is not None:  # absent from earlier setups
                    setup["gnn_rollout_greedy_after"] = self.gnn_rollout_greedy_after
        elif method == "expert":
            setup["expert_iterations"] = self.expert_iterations
        return setup


MISSION_METHODS = ("greedy", "greedy_stay", "gnn", "expert")


def make_mission_policy(method: str, config: MissionConfig) -> Any:
    """The policy of ``method`` for the mission (the GNN and the expert import lazily)."""
    from marl_cover.agents.baselines.greedy import GreedyPolicy

    if method == "greedy":
        return GreedyPolicy(config.hops, fallback="random")
    if method == "greedy_stay":
        return GreedyPolicy(config.hops, fallback="stay")
    if method == "gnn":
        from marl_cover.agents.models.checkpoints import load_model
        from marl_cover.agents.models.policy import GNNPolicy

        model, _ = load_model(config.gnn_model_path())
        if config.gnn_rollout is not None:
            from marl_cover.agents.planners.local_rollout import LocalRolloutPolicy

            return LocalRolloutPolicy(
                model,
                margin=config.gnn_rollout,
                horizon=config.gnn_rollout_horizon,
                greedy_after=config.gnn_rollout_greedy_after,
            )
        return GNNPolicy(model, centralized=config.gnn_centralized, spread_margin=config.gnn_spread)
    if method == "expert":
        return MissionExpert(RoutingExpert(max_iterations=config.expert_iterations))
    raise ValueError(f"unknown mission method {method!r}; choose from {MISSION_METHODS}")
