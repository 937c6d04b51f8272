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
    """

    agreed: int
    total: int
    by_step: dict[int, list[int]] = field(default_factory=dict)

    @property
    def fraction(self) -> float:
        """``agreed / total`` (NaN when nothing was compared)."""
        return self.agreed / self.total if self.total else math.nan


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
    for done, episode in enumerate(episodes, start=1):
        count = min(states_per_episode, episode.num_steps)
        steps = np.sort(rng.choice(episode.num_steps, size=count, replace=False))
        env.reset(seed=episode.seed)
        step = 0
        for target in steps.tolist():
            while step < target:
                env.step(
                    dict(zip(env.possible_agents, episode.actions[step].tolist(), strict=True))
                )
                step += 1
            if not np.array_equal(env.snapshot().robot_node, episode.robot_node[step]):
                raise ValueError(
                    f"episode seed {episode.seed} left its recorded positions at step {step}: "
                    "is the environment configured as when it was recorded?"
                )
            same = np.asarray(relabel(env, step)) == episode.actions[step]
            counts = by_step.setdefault(bucket * (step // bucket), [0, 0])
            counts[0] += int(same.sum())
            counts[1] += len(same)
        if progress is not None:
            progress(done)
    agreed = sum(counts[0] for counts in by_step.values())
    total = sum(counts[1] for counts in by_step.values())
    return Agreement(agreed, total, dict(sorted(by_step.items())))


def with_steps_left(snapshot: CoverageSnapshot, steps_left: int) -> CoverageSnapshot:
    """``snapshot`` with its clock set to ``steps_left`` actions left (a planner given it is
    blind to the real time: what a policy without a clock would have to assume)."""
    if steps_left < 1:
        raise ValueError(f"steps_left must be >= 1, got {steps_left}")
    return dataclasses.replace(snapshot, num_steps=snapshot.max_steps - steps_left)
