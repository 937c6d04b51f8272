"""The actions a step is given, read and checked: one integer in ``[0, 5)`` per live agent."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from marl_cover.ego import NUM_ACTIONS


def is_action(value: Any) -> bool:
    """Whether ``value`` is an integer action in ``[0, NUM_ACTIONS)`` (integral floats count)."""
    if isinstance(value, (bool, np.bool_, str, bytes)) or np.ndim(value) != 0:
        return False
    try:
        number = float(value)  # Python and numpy numbers, 0-d arrays and tensors
    except (TypeError, ValueError):
        return False
    return number.is_integer() and 0 <= number < NUM_ACTIONS


#: Action types read without a check per action (``bool`` is not one of them).
_PLAIN_INTEGERS = {int, np.int64, np.int32, np.int16, np.int8, np.uint8, np.uint16, np.uint32}


def read_actions(actions: dict[str, Any], live: Sequence[str], agents: Sequence[str]) -> np.ndarray:
    """The action of each of ``agents`` in order, ``(R,)`` int64.

    Args:
        actions: Agent name -> action, for every ``live`` agent.
        live: The agents that must act.
        agents: Every agent, in the order of the result.

    Raises:
        ValueError: an agent is unknown or missing, or an action is not an integer in
            ``[0, 5)``; the message names the agent.
    """
    known = set(agents)
    unknown = [a for a in actions if a not in known]
    if unknown:
        raise ValueError(
            f"actions given for unknown agents {unknown}; the agents are {list(agents)}"
        )
    missing = [a for a in live if a not in actions]
    if missing:
        raise ValueError(f"no action given for {missing}")
    values = [actions[agent] for agent in agents]
    if set(map(type, values)) <= _PLAIN_INTEGERS:  # the common case, checked at once
        try:
            action = np.array(values, dtype=np.int64)
        except OverflowError:  # a huge integer: the check below names it
            pass
        else:
            if len(action) == 0 or (action.min() >= 0 and action.max() < NUM_ACTIONS):
                return action
    action = np.empty(len(agents), dtype=np.int64)
    for i, agent in enumerate(agents):
        value = actions[agent]
        if not is_action(value):
            raise ValueError(f"action of {agent} must be an integer in [0, 5), got {value!r}")
        action[i] = int(value)
    return action
