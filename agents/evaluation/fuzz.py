"""A fuzz harness for the environment: random maps, teams and settings, random, illegal and
malformed actions, and the environment's invariants checked after every step.

Each case is one episode drawn from ``numpy.random.default_rng([seed, case])``: a map (a
procedural city, a random lattice, or a jittered graph that is not a lattice), a task, a team
of 1 to ``max_robots`` robots and the environment's settings. Every step draws each robot's
action among its legal moves or, with probability ``illegal_fraction``, among its masked-out
ones; now and then a malformed action dictionary comes first (an unknown or missing agent, an
action out of range, of another type), which must be refused with a ``ValueError`` and change
nothing. After every step:

==================  ===========================================================================
invariant           what is checked
==================  ===========================================================================
``no_sharing``      no two robots on one waypoint
``edges_only``      every robot stayed or moved to a neighbour; a legal, unblocked move reached
                    its target; a masked-out action is a no-op (or a ``ValueError`` naming the
                    robot with ``invalid_action="raise"``)
``masks``           every ``action_mask`` equals the legal moves of its robot's waypoint
``reward``          the team reward is finite and equals the points of interest first visited
                    this step, and the ``new_interest`` infos add up to it
``episode_end``     terminated iff every point of interest is visited; truncated iff out of
                    steps and not terminated; no live agents after either
``obs_space``       every observation lies inside its agent's ``observation_space``
``refusals``        a malformed action dictionary raised ``ValueError`` and changed nothing
``replay``          (one case in ``replay_every``) the same seed and actions give the same
                    episode, bit for bit
``crash``           nothing else raised: any other exception ends the case as a violation
                    (its type and message)
==================  ===========================================================================

A violation is reported with its case; ``marl-cover fuzz seed=S cases=[C]`` plays that case
alone.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import marl_cover
from marl_cover.graph import SpatialGraph
from marl_cover.maps import graph_from_occupancy

INVARIANTS = (
    "no_sharing",
    "edges_only",
    "masks",
    "reward",
    "episode_end",
    "obs_space",
    "refusals",
    "replay",
    "crash",
)


@dataclass
class FuzzReport:
    """What a fuzz run did and found.

    Attributes:
        cases: Episodes played.
        env_steps: Steps taken.
        agent_steps: Agent-steps (live agents summed over steps).
        refused_inputs: Malformed or illegal action dictionaries refused as expected.
        violations: One record per broken invariant: case, step, invariant, message.
        seconds: Wall time.
        settings: Count of cases by map kind, task and ``invalid_action`` mode.
    """

    cases: int = 0
    env_steps: int = 0
    agent_steps: int = 0
    refused_inputs: int = 0
    violations: list[dict[str, Any]] = field(default_factory=list)
    seconds: float = 0.0
    settings: Counter[str] = field(default_factory=Counter)

    def counts(self) -> dict[str, int]:
        """Violations by invariant (every invariant listed)."""
        found = Counter(v["invariant"] for v in self.violations)
        return {name: found.get(name, 0) for name in INVARIANTS}


class _Violation(Exception):
    def __init__(self, invariant: str, message: str) -> None:
        super().__init__(message)
        self.invariant = invariant


def _check(condition: bool, invariant: str, message: str) -> None:
    if not condition:
        raise _Violation(invariant, message)


# ---------------------------------------------------------------------- random cases
def random_lattice(rng: np.random.Generator, max_waypoints: int) -> SpatialGraph:
    """The largest component of random free cells of a grid (5 m cells)."""
    side = int(rng.integers(2, max(3, int(math.sqrt(2 * max_waypoints)) + 1)))
    cols = int(rng.integers(1, side + 1))
    occupied = rng.random((side, cols)) < rng.uniform(0.0, 0.45)
    occupied[rng.integers(side), rng.integers(cols)] = False
    return graph_from_occupancy(occupied, cell_size=5.0)


def random_jittered_graph(rng: np.random.Generator, max_waypoints: int) -> SpatialGraph:
    """A lattice with randomly dropped edges and jittered positions: not a lattice (no grid
    cells), uneven edge lengths, and possibly several components (the largest is kept)."""
    side = int(rng.integers(2, max(3, int(math.sqrt(max_waypoints)) + 1)))
    ids = np.arange(side * side).reshape(side, side)
    edges = np.concatenate(
        [
            np.stack([ids[:, :-1].ravel(), ids[:, 1:].ravel()], axis=1),
            np.stack([ids[:-1, :].ravel(), ids[1:, :].ravel()], axis=1),
        ]
    )
    edges = edges[rng.random(len(edges)) > rng.uniform(0.0, 0.3)]
    grid = np.stack(np.divmod(np.arange(side * side), side), axis=1)[:, ::-1].astype(float)
    positions = (grid + rng.uniform(-0.2, 0.2, grid.shape)) * 3.0  # about 3 m apart
    return SpatialGraph.from_edges(positions, edges, cell_size=3.0).largest_component()


def random_case(rng: np.random.Generator, max_robots: int, max_waypoints: int) -> dict[str, Any]:
    """The environment settings of one case (``parallel_env`` keyword arguments)."""
    kind = ("city", "lattice", "jittered")[int(rng.integers(3))]
    settings: dict[str, Any] = {}
    if kind == "city":
        settings.update(map="city", city_size=int(rng.integers(10, max_waypoints + 1)))
        num_nodes, cell = settings["city_size"], 5.0
    else:
        make = random_lattice if kind == "lattice" else random_jittered_graph
        graph = make(rng, max_waypoints)
        settings["graph"] = graph
        num_nodes, cell = graph.num_nodes, graph.cell_size
    top = min(max_robots, num_nodes)
    num_robots = int(np.exp(rng.uniform(0.0, np.log(top + 1))))  # log-uniform in 1..top
    if rng.random() < 0.1:  # the largest team the map takes (up to max_robots), packed
        num_robots = top
    task = ("coverage", "exploration")[int(rng.integers(2))]
    settings.update(
        task=task,
        num_robots=max(1, min(num_robots, top)),
        max_steps=int(rng.integers(1, 41)),
        hops=int(rng.choice([1, 2, 3, 5, 8, 19])),
        interest_fraction=float(rng.choice([0.0, 0.1, 0.5, 1.0])),
        start_density=int(rng.integers(1, 8)),
        allow_swaps=bool(rng.integers(2)),
        invalid_action=("noop", "raise")[int(rng.integers(2))],
        sensor_range=float(cell * rng.uniform(1.5, 5.0)),
    )
    return {"kind": kind, **settings}


def _malformed(rng: np.random.Generator, agents: list[str]) -> dict[str, Any]:
    """An action dictionary ``step`` must refuse."""
    good = {a: 0 for a in agents}
    victim = agents[int(rng.integers(len(agents)))]
    kind = int(rng.integers(6))
    if kind == 0:
        return {**good, "robot_999999": 0}  # unknown agent
    if kind == 1:
        return {a: 0 for a in agents if a != victim}  # missing agent
    value: Any = [5, -1, 1.5, "1", None, np.array([1, 2])][int(rng.integers(6))]
    if kind == 2:
        value = 5 + int(rng.integers(100))
    return {**good, victim: value}


# ---------------------------------------------------------------------- one case
def play_case(
    seed: int,
    case: int,
    max_robots: int,
    max_waypoints: int,
    illegal_fraction: float,
    malformed_fraction: float,
    report: FuzzReport,
    actions_out: list[dict[str, int]] | None = None,
    given_actions: list[dict[str, int]] | None = None,
) -> list[float]:
    """Plays one case, checking every invariant; returns the team rewards of its steps.

    Raises:
        _Violation: the first broken invariant.
    """
    rng = np.random.default_rng([seed, case])
    settings = random_case(rng, max_robots, max_waypoints)
    kind = settings.pop("kind")
    report.settings[f"map={kind}"] += 1
    report.settings[f"task={settings['task']}"] += 1
    report.settings[f"invalid_action={settings['invalid_action']}"] += 1
    report.settings[f"robots={_bucket(settings['num_robots'])}"] += 1
    env = marl_cover.parallel_env(**settings)
    obs, _ = env.reset(seed=int(rng.integers(2**31)))
    space = env.observation_space(env.possible_agents[0])
    rewards_seen: list[float] = []
    step = 0
    while env.agents:
        before = env.snapshot()
        graph, node = before.graph, before.robot_node
        legal = _legal(graph, node)  # (R, 5)
        for i, agent in enumerate(env.agents):
            mask = obs[agent]["action_mask"].astype(bool)
            _check(
                np.array_equal(mask, legal[i]),
                "masks",
                f"step {step}: {agent} on waypoint {node[i]} has mask {mask.astype(int)}, "
                f"legal moves {legal[i].astype(int)}",
            )
            _check(space.contains(obs[agent]), "obs_space", f"step {step}: {agent}'s observation")
        if given_actions is None and rng.random() < malformed_fraction:
            _refused(env, _malformed(rng, env.agents), before, step)
            report.refused_inputs += 1
        if given_actions is not None:
            actions = given_actions[step]
        else:
            actions = _draw_actions(rng, env.agents, legal, illegal_fraction)
        illegal = np.array([not legal[i, actions[a]] for i, a in enumerate(env.agents)])
        if settings["invalid_action"] == "raise" and illegal.any():
            first = env.agents[int(np.flatnonzero(illegal)[0])]
            _refused(env, actions, before, step, must_name=first)
            report.refused_inputs += 1
            actions = {a: (actions[a] if not illegal[i] else 0) for i, a in enumerate(env.agents)}
            illegal[:] = False
        if actions_out is not None:
            actions_out.append(dict(actions))
        live = len(env.agents)
        obs, rewards, terminations, truncations, infos = env.step(actions)
        after = env.snapshot()
        _check_step(before, after, actions, illegal, rewards, infos, step)
        _check_end(env, before, after, terminations, truncations, step)
        rewards_seen.append(float(rewards[next(iter(rewards))]) if rewards else 0.0)
        report.env_steps += 1
        report.agent_steps += live
        step += 1
    return rewards_seen


def _bucket(num_robots: int) -> str:
    """A team size's bucket in the report: 1, 2-9, 10-99, 100+."""
    if num_robots == 1:
        return "1"
    return "2-9" if num_robots < 10 else "10-99" if num_robots < 100 else "100+"


def _legal(graph: SpatialGraph, node: np.ndarray) -> np.ndarray:
    """Legal actions ``(R, 5)`` bool: stay, and each slot with a neighbour."""
    return np.concatenate([np.ones((len(node), 1), dtype=bool), graph.neighbors[node] >= 0], axis=1)


def _draw_actions(
    rng: np.random.Generator, agents: list[str], legal: np.ndarray, illegal_fraction: float
) -> dict[str, int]:
    actions = {}
    for i, agent in enumerate(agents):
        pool = np.flatnonzero(~legal[i]) if rng.random() < illegal_fraction else np.zeros(0)
        if len(pool) == 0:
            pool = np.flatnonzero(legal[i])
        actions[agent] = int(rng.choice(pool))
    return actions


def _refused(
    env: Any, actions: dict[str, Any], before: Any, step: int, must_name: str | None = None
) -> None:
    """``step(actions)`` must raise ``ValueError`` (naming ``must_name``) and change nothing."""
    try:
        env.step(actions)
    except ValueError as error:
        _check(
            must_name is None or must_name in str(error),
            "refusals",
            f"step {step}: the error does not name {must_name}: {error}",
        )
    else:
        raise _Violation("refusals", f"step {step}: step({actions!r}) was accepted")
    after = env.snapshot()
    _check(
        np.array_equal(after.robot_node, before.robot_node)
        and np.array_equal(after.visited, before.visited)
        and after.num_steps == before.num_steps,
        "refusals",
        f"step {step}: a refused step({actions!r}) changed the episode",
    )


def _check_step(
    before: Any,
    after: Any,
    actions: dict[str, int],
    illegal: np.ndarray,
    rewards: dict[str, float],
    infos: dict[str, dict[str, Any]],
    step: int,
) -> None:
    graph, old, new = before.graph, before.robot_node, after.robot_node
    _check(
        len(np.unique(new)) == len(new),
        "no_sharing",
        f"step {step}: robots share waypoints {np.sort(new).tolist()}",
    )
    agents = list(actions)
    for i, agent in enumerate(agents):
        neighbours = graph.neighbors[old[i]]
        _check(
            new[i] == old[i] or new[i] in neighbours,
            "edges_only",
            f"step {step}: {agent} jumped from {old[i]} to {new[i]}",
        )
        action = actions[agent]
        target = old[i] if action == 0 or illegal[i] else neighbours[action - 1]
        blocked = bool(infos[agent].get("blocked", False))
        _check(
            bool(infos[agent].get("invalid_action")) == bool(illegal[i]),
            "edges_only",
            f"step {step}: {agent}'s action {action} is reported invalid "
            f"{infos[agent].get('invalid_action')}, but it is {'' if illegal[i] else 'not '}masked",
        )
        _check(
            new[i] == (old[i] if blocked else target),
            "edges_only",
            f"step {step}: {agent} took action {action} from {old[i]} to {new[i]} "
            f"(target {target}, blocked {blocked})",
        )
    expected = int((before.interest & ~before.visited)[np.unique(new)].sum())
    values = set(rewards.values())
    _check(
        len(values) == 1 and all(math.isfinite(v) for v in values),
        "reward",
        f"step {step}: rewards {rewards} are not one finite team reward",
    )
    reward = values.pop()
    credited = sum(int(info.get("new_interest", 0)) for info in infos.values())
    _check(
        reward == expected and credited == expected,
        "reward",
        f"step {step}: reward {reward}, infos credit {credited}, new points {expected}",
    )


def _check_end(
    env: Any,
    before: Any,
    after: Any,
    terminations: dict[str, bool],
    truncations: dict[str, bool],
    step: int,
) -> None:
    done = not (after.interest & ~after.visited).any()
    out_of_time = after.num_steps >= after.max_steps
    terminated, truncated = any(terminations.values()), any(truncations.values())
    _check(
        terminated == done and truncated == (out_of_time and not done),
        "episode_end",
        f"step {step}: terminated {terminated} (all covered: {done}), truncated {truncated} "
        f"(steps {after.num_steps} of {after.max_steps})",
    )
    _check(
        (env.agents == []) == (terminated or truncated),
        "episode_end",
        f"step {step}: live agents {len(env.agents)} after terminated {terminated}, "
        f"truncated {truncated}",
    )


# ---------------------------------------------------------------------- a run
def fuzz(
    agent_steps: int,
    seed: int = 0,
    max_robots: int = 100,
    max_waypoints: int = 400,
    illegal_fraction: float = 0.1,
    malformed_fraction: float = 0.05,
    replay_every: int = 10,
    cases: list[int] | None = None,
    progress: Any = None,
) -> FuzzReport:
    """Plays cases ``0, 1, ...`` (or ``cases``) until ``agent_steps`` agent-steps are run.

    Args:
        agent_steps: Stop after the case that passes this many agent-steps.
        seed: The run's seed; case ``c`` draws from ``default_rng([seed, c])``.
        max_robots: Largest team.
        max_waypoints: Largest map.
        illegal_fraction: Chance that a robot's action is drawn among its masked-out ones.
        malformed_fraction: Chance per step of a malformed action dictionary first.
        replay_every: Replay one case in this many and compare (0: never).
        cases: Play exactly these cases (to reproduce a report's violation).
        progress: Called with the agent-steps of each case as it ends.
    """
    report = FuzzReport()
    start = time.perf_counter()
    case = 0
    todo = list(cases) if cases is not None else None
    while (todo is None and report.agent_steps < agent_steps) or todo:
        case = todo.pop(0) if todo else case
        args = (seed, case, max_robots, max_waypoints, illegal_fraction, malformed_fraction)
        before = report.agent_steps
        actions: list[dict[str, int]] = []
        try:
            rewards = play_case(*args, report, actions_out=actions)
            if replay_every and case % replay_every == 0:
                again = play_case(*args, FuzzReport(), given_actions=actions)
                _check(again == rewards, "replay", f"rewards {again} on replay, {rewards} first")
        except _Violation as violation:
            report.violations.append(
                {"case": case, "invariant": violation.invariant, "message": str(violation)}
            )
        except Exception as error:  # noqa: BLE001 (a crash is what a fuzzer reports)
            message = f"{type(error).__name__}: {error}"
            report.violations.append({"case": case, "invariant": "crash", "message": message})
        report.cases += 1
        if progress is not None:
            progress(report.agent_steps - before)
        case += 1
    report.seconds = time.perf_counter() - start
    return report
