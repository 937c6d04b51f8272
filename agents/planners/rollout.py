"""One-step rollout improvement of a base policy, by exact simulation.

Coverage and exploration are deterministic once an episode has started: the same actions from
the same state give the same future. So the return of a joint action followed by a base policy
is computed exactly by playing the episode out on copies of the environment
(:func:`fork`), and the one-step rollout policy (Bertsekas' rollout) takes, for each robot,
the move whose play-out returns most:

- ``sequential=True`` (multiagent rollout, one robot at a time): robot ``i`` tries its moves
  with robots ``0..i-1`` on the moves already chosen and the others on the base policy's. A
  move replaces the base policy's only when it returns strictly more, so each step's joint
  action returns at least the base policy's from that state, and the rollout policy's episode
  returns at least the base policy's (tested).
- ``sequential=False`` (every robot against the base policy's joint action): each robot's best
  single deviation, all evaluated in one batch: each robot's best response to a team that
  plays the base policy, as labels for a decentralized learner. Their combination has no
  guarantee (and a GNN trained on them got worse: the "what we tried" page of the docs).

The rollout policy reads the whole state and plays the future out: it is an omniscient planner,
as the routing experts are. All play-outs of a decision run in lockstep, so a
network base decides for all of them in one batched pass (:class:`GNNArgmax`).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from marl_cover.env import CoverageEnv


class BasePolicy(Protocol):
    """A centralized policy over a batch of states: ``(B, R)`` integer actions for ``B``
    ``state()`` dictionaries (every state of one environment configuration)."""

    def __call__(self, states: list[dict[str, np.ndarray]]) -> np.ndarray:
        """Actions ``(B, R)`` for the ``B`` states."""


class GNNArgmax:
    """A GNN's argmax actions for a batch of states, in one pass (a :class:`BasePolicy`).

    Args:
        model: An :class:`~marl_cover.agents.models.gnn.AggregationGNN`.
    """

    def __init__(self, model: Any) -> None:
        self.model = model.eval()
        self._dtype = next(model.parameters()).dtype

    def __call__(self, states: list[dict[str, np.ndarray]]) -> np.ndarray:
        """Each robot's argmax action ``(B, R)`` in each of the ``B`` states."""
        import torch

        from marl_cover.agents.models.logits import batched_state_logits

        keys = [key for key in states[0] if key != "robot_nodes"]
        batch = {}
        for key in keys:
            tensor = torch.from_numpy(np.stack([np.asarray(s[key]) for s in states]))
            batch[key] = tensor.to(self._dtype) if tensor.is_floating_point() else tensor
        num_robots = len(states[0]["robot_nodes"])
        with torch.inference_mode():
            logits = batched_state_logits(self.model, batch, num_robots)  # (B, R, 5)
        return logits.argmax(dim=-1).numpy()


def fork(env: CoverageEnv) -> CoverageEnv:
    """An independent copy of ``env`` mid-episode (:meth:`CoverageEnv.fork`: what no step
    changes is shared)."""
    return env.fork()


def play_out(
    env: CoverageEnv,
    base: BasePolicy,
    joints: np.ndarray,
    steps: int | None = None,
    finish: Callable[[CoverageEnv], float] | None = None,
) -> np.ndarray:
    """The exact return of each joint action followed by ``base`` to the end of the episode.

    Args:
        env: The environment mid-episode (left unchanged).
        base: The policy every robot follows after the first step.
        joints: ``(J, R)`` first-step actions (unmasked moves; a masked one is a stay).
        steps: Play only this many steps (the joint action's included) on ``base``
            (``None``: to the end of the episode).
        finish: With ``steps``: the return of the rest of the episode from where a play-out
            stands (for instance a cheaper policy's,
            :func:`marl_cover.agents.baselines.greedy.greedy_return`).

    Returns:
        ``(J,)`` float: the team reward from this step to the end, for each joint action.

    Raises:
        ValueError: ``steps`` is below 1 (the joint action is always played).
    """
    if steps is not None and steps < 1:
        raise ValueError(f"play_out plays at least the joint action's step, got steps={steps}")
    forks = [fork(env) for _ in joints]
    totals = np.array(
        [
            float(f.apply_actions(np.asarray(j)).new_interest.sum())
            for f, j in zip(forks, joints, strict=True)
        ]
    )
    played = 1
    live = [k for k, f in enumerate(forks) if f.agents]
    while live and (steps is None or played < steps):
        actions = base([forks[k].state() for k in live])  # (len(live), R)
        for k, action in zip(live, actions, strict=True):
            totals[k] += float(forks[k].apply_actions(action).new_interest.sum())
        live = [k for k in live if forks[k].agents]
        played += 1
    if finish is not None:
        for k in live:
            totals[k] += finish(forks[k])
    return totals


def play_out_greedy_finish(
    env: CoverageEnv,
    base: BasePolicy,
    joints: np.ndarray,
    greedy_after: int | None,
    hops: int,
) -> np.ndarray:
    """:func:`play_out` with ``base`` for ``greedy_after`` steps (the joint action's
    included) and greedy with horizon ``hops`` to the end
    (:func:`marl_cover.agents.baselines.greedy.greedy_return`); ``greedy_after=None``: ``base`` to
    the end."""
    if greedy_after is None:
        return play_out(env, base, joints)
    from marl_cover.agents.baselines.greedy import greedy_return

    return play_out(
        env, base, joints, steps=greedy_after, finish=lambda rest: greedy_return(rest, hops)
    )


class RolloutPolicy:
    """The one-step rollout policy of a base policy (see the module docstring).

    Args:
        base: The base policy of the play-outs.
        sequential: Robot by robot (never worse than ``base``) or every robot against the
            base's joint action.
        greedy_after: After this many steps of a play-out (the joint action's included),
            greedy plays the rest (with the environment's horizon K, staying when nothing is
            within reach: :func:`~marl_cover.agents.baselines.greedy.greedy_return`, a compiled
            play-out of tens of microseconds; coverage only); ``None``: ``base`` to the end. A
            play-out that hands over from ``base`` to greedy after a few moves can rank moves
            worse than either alone.

    Attributes:
        accept: After :meth:`improve`: ``(R,)`` bit masks of the moves that returned as much as
            the chosen one (bit ``a`` for action ``a``), as the routing experts record them.
        counts: ``decisions`` (robot decisions), ``changed`` (those that left the base
            policy's move) and ``play_outs``.

    Raises:
        ValueError: ``greedy_after`` is below 1.
    """

    def __init__(
        self, base: BasePolicy, sequential: bool = True, greedy_after: int | None = None
    ) -> None:
        if greedy_after is not None and greedy_after < 1:
            raise ValueError(
                f"the rollout's greedy_after must be >= 1 step (the joint action's), got "
                f"{greedy_after}"
            )
        self.base = base
        self.sequential = sequential
        self.greedy_after = greedy_after
        self.accept = np.zeros(0, dtype=np.int64)
        self.counts: Counter[str] = Counter()

    def reset(self, seed: int | None = None) -> None:  # noqa: ARG002 (the harness's hook)
        """Starts an episode: zeroes the counts (the evaluation harness's hook)."""
        self.counts = Counter()

    def improve(self, env: CoverageEnv) -> np.ndarray:
        """Every robot's move ``(R,)`` at the environment's current state (left unchanged)."""
        state = env.state()
        chosen = np.asarray(self.base([state])[0]).copy()  # (R,)
        base_action = chosen.copy()
        allowed = np.asarray(state["action_mask"], dtype=bool)  # (R, 5)
        num_robots = len(chosen)
        accept = np.zeros(num_robots, dtype=np.int64)
        groups = [[i] for i in range(num_robots)] if self.sequential else [range(num_robots)]
        current = None  # the return of ``chosen`` as it stands, once known
        for robots in groups:
            joints, owner = [], []
            for i in robots:
                for move in np.flatnonzero(allowed[i]).tolist():
                    if move != chosen[i]:
                        joint = chosen.copy()
                        joint[i] = move
                        joints.append(joint)
                        owner.append((i, move))
            if current is None:
                joints.insert(0, chosen.copy())
            values = self._play_outs(env, np.array(joints)) if joints else np.zeros(0)
            self.counts["play_outs"] += len(joints)
            if current is None:
                current, values = float(values[0]), values[1:]
            start = chosen.copy()
            best_of_group = current
            for i in robots:
                returns = {int(start[i]): current}
                for (robot, move), value in zip(owner, values, strict=True):
                    if robot == i:
                        returns[move] = float(value)
                best = max(returns.values())
                if best > current:  # a strictly better move; among equals, the lowest
                    chosen[i] = min(m for m, v in returns.items() if v == best)
                accept[i] = sum(1 << m for m, v in returns.items() if v == best)
                best_of_group = max(best_of_group, best)
            if self.sequential:
                current = best_of_group  # the return of the joint action with robot i's move
        self.accept = accept
        self.counts["decisions"] += num_robots
        self.counts["changed"] += int((chosen != base_action).sum())
        return chosen

    def _play_outs(self, env: CoverageEnv, joints: np.ndarray) -> np.ndarray:
        """The return ``(J,)`` of each joint action: ``base`` to the end, or greedy after
        ``greedy_after`` steps."""
        return play_out_greedy_finish(env, self.base, joints, self.greedy_after, env.config.hops)

    def act_env(self, env: CoverageEnv) -> dict[str, int]:
        """The rollout policy's actions (the evaluation harness's interface)."""
        return dict(zip(env.possible_agents, self.improve(env).tolist(), strict=True))
