"""How well a recorded action is determined by the state it was taken in.

Behaviour cloning learns a function of the state. An open-loop expert's label at step ``t``
comes from a plan made at step 0, so it need not be what a plan made *at* step ``t`` would do:
the fraction of recorded labels that a fresh plan from the same state reproduces bounds how well
any policy of the state can match the labels. :func:`label_agreement` measures it: it replays
recorded episodes to sampled steps (same seed, same actions, same states) and compares each
robot's recorded action with a relabelling of that state.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from agents.datasets import Episode
from marl_cover.env import CoverageEnv, CoverageSnapshot


@dataclass(frozen=True)
class Agreement:
    """Agreement of recorded labels with relabelled ones.

    Attributes:
        agreed: Robot-states whose relabelled action equals the recorded one.
        total: Robot-states compared.
        by_step: Step bucket start (``bucket * (t // bucket)``) -> ``[agreed, total]``.
        in_set: Robot-states whose relabelled action is in the recorded set of equally good
            actions (``Episode.accept``; equals ``agreed`` for episodes without sets).
        tied: Robot-states whose recorded set holds more than the label.
    """

    agreed: int
    total: int
    by_step: dict[int, list[int]] = field(default_factory=dict)
    in_set: int = 0
    tied: int = 0

    @property
    def fraction(self) -> float:
        """``agreed / total`` (NaN when nothing was compared)."""
        return self.agreed / self.total if self.total else math.nan

    @property
    def set_fraction(self) -> float:
        """Share of robot-states whose relabelled action is one the recorded expert rated as
        good as its label (:attr:`Episode.accept`; the label alone where not recorded)."""
        return self.in_set / self.total if self.total else math.nan

    @property
    def tied_fraction(self) -> float:
        """Share of robot-states whose recorded label had an equally good alternative."""
        return self.tied / self.total if self.total else math.nan


def label_agreement(
    env: CoverageEnv,
    episodes: Sequence[Episode],
    relabel: Callable[[CoverageEnv, int], np.ndarray],
    states_per_episode: int,
    rng: np.random.Generator,
    bucket: int = 10,
    progress: Callable[[int], None] | None = None,
) -> Agreement:
    """Compares recorded actions with ``relabel`` at sampled steps of each episode.

    Args:
        env: An environment with the settings the episodes were recorded under.
        episodes: Recorded episodes.
        relabel: ``(env, step) -> (R,)`` actions for the env's current state (e.g. a fresh
            expert plan).
        states_per_episode: Distinct steps sampled per episode (all when it has fewer).
        rng: Chooses the steps.
        bucket: Width of the step buckets of ``by_step``.
        progress: Called with the number of episodes done.

    Raises:
        ValueError: a replayed episode leaves its recorded positions (another map, other
            settings), naming its seed and step.
    """
    by_step: dict[int, list[int]] = {}
    in_set = tied = 0
    for done, episode in enumerate(episodes, start=1):
        count = min(states_per_episode, episode.num_steps)
        steps = np.sort(rng.choice(episode.num_steps, size=count, replace=False))
        moves = recorded_moves(episode)  # (T, R)
        labels = episode.actions.astype(np.int64)
        accept = episode.label_sets()  # (T, R)
        env.reset(seed=episode.seed)
        step = 0
        for target in steps.tolist():
            while step < target:
                env.step(dict(zip(env.possible_agents, moves[step].tolist(), strict=True)))
                step += 1
            if not np.array_equal(env.snapshot().robot_node, episode.robot_node[step]):
                raise ValueError(
                    f"episode seed {episode.seed} left its recorded positions at step {step}: "
                    "is the environment configured as when it was recorded?"
                )
            action = np.asarray(relabel(env, step), dtype=np.int64)
            same = action == labels[step]
            in_set += int(((accept[step] >> action) & 1).sum())
            tied += int((accept[step] != 1 << labels[step]).sum())
            counts = by_step.setdefault(bucket * (step // bucket), [0, 0])
            counts[0] += int(same.sum())
            counts[1] += len(same)
        if progress is not None:
            progress(done)
    agreed = sum(counts[0] for counts in by_step.values())
    total = sum(counts[1] for counts in by_step.values())
    return Agreement(agreed, total, dict(sorted(by_step.items())), in_set, tied)


def recorded_moves(episode: Episode) -> np.ndarray:
    """The action that carries each robot from one recorded waypoint to the next, ``(T, R)``
    (0 where it stayed). Replaying them gives the recorded states whether the labels were
    carried out (an expert's episode) or not (DAgger: the learner moved, the expert labelled).

    Raises:
        ValueError: two recorded waypoints are not neighbours, naming the episode and step.
    """
    here, there = episode.robot_node[:-1], episode.robot_node[1:]  # (T, R)
    slots = episode.graph.neighbors[here] == there[..., None]  # (T, R, 4)
    moved = slots.any(-1)
    legal = (moved | (here == there)).all(-1)  # (T,)
    if not legal.all():
        step = int(np.flatnonzero(~legal)[0])
        raise ValueError(f"episode seed {episode.seed} jumps between waypoints at step {step}")
    return np.where(moved, slots.argmax(-1) + 1, 0)


def with_steps_left(snapshot: CoverageSnapshot, steps_left: int) -> CoverageSnapshot:
    """``snapshot`` with its clock set to ``steps_left`` actions left (a planner given it is
    blind to the real time: what a policy without a clock would have to assume)."""
    if steps_left < 1:
        raise ValueError(f"steps_left must be >= 1, got {steps_left}")
    return dataclasses.replace(snapshot, num_steps=snapshot.max_steps - steps_left)
