"""The GNN as a policy in the evaluation harness (:class:`GNNPolicy`).

Decentralized (each robot on its own ego-graph: :meth:`GNNPolicy.act` on padded observations,
:meth:`GNNPolicy.act_compact` on compact tables) or centralized (one pass on ``state()``,
:meth:`GNNPolicy.act_state`), greedy (argmax) by default.
"""

from __future__ import annotations

import numpy as np
import torch

from marl_cover.agents.baselines.spread import spread_actions
from marl_cover.agents.models.actors import GRAPH_KEYS
from marl_cover.agents.models.gnn import AggregationGNN
from marl_cover.agents.models.logits import (
    centralized_logits,
    compact_logits,
    decentralized_logits,
)
from marl_cover.compact import CompactObservations


class GNNPolicy:
    """The GNN in the evaluation harness.

    The two modes compute the same logits up to float rounding (the sums run in another
    order), so in float32 an action whose logit ties another within ~1e-6 can differ between
    them; a float64 model (``model.double()``) gives the same actions in both.

    Args:
        model: A trained network.
        centralized: Decide all robots in one pass over ``state()`` instead of one ego-graph
            per robot (same actions; faster for large teams).
        deterministic: Argmax (default) or sample from the masked categorical.
        seed: Seed of the sampling generator (reset with each episode's seed).
        temperature: Divides the logits before sampling (below 1: sharper, toward the argmax
            with near-ties broken at random; see :class:`Tempered`). Unused by the argmax.
        spread_margin: Break near-ties of the argmax (moves within this much of the best
            logit) toward the move that leads farthest from the nearest teammate in the robot's
            ego-graph (:mod:`marl_cover.agents.baselines.spread`); ``None``: the plain argmax.
            Decentralized and deterministic only.

    Raises:
        ValueError: ``temperature`` is not positive, or ``spread_margin`` is negative or given
            with ``centralized`` or sampling.
    """

    def __init__(
        self,
        model: AggregationGNN,
        centralized: bool = False,
        deterministic: bool = True,
        seed: int = 0,
        temperature: float = 1.0,
        spread_margin: float | None = None,
    ) -> None:
        if not temperature > 0:
            raise ValueError(f"temperature must be > 0, got {temperature}")
        if spread_margin is not None and (centralized or not deterministic):
            raise ValueError(
                "spread_margin breaks ties of the argmax on each robot's ego-graph: it needs "
                "centralized=False and deterministic=True"
            )
        if spread_margin is not None and not spread_margin >= 0:
            raise ValueError(f"spread_margin must be >= 0, got {spread_margin}")
        self.spread_margin = spread_margin
        self.model = model.eval()
        self._dtype = next(model.parameters()).dtype
        self.centralized = centralized
        self.deterministic = deterministic
        self.temperature = temperature
        self._generator = torch.Generator().manual_seed(seed)
        if centralized:
            self.act_state = self._act_state

    def reset(self, seed: int | None = None) -> None:
        """Reseeds the sampling generator for an episode (``None``: keeps it)."""
        if seed is not None:
            self._generator.manual_seed(seed)

    def _choose(self, logits: torch.Tensor) -> np.ndarray:
        if self.deterministic:
            return logits.argmax(dim=-1).numpy()
        probs = torch.softmax(logits / self.temperature, dim=-1)
        return torch.multinomial(probs, 1, generator=self._generator).squeeze(-1).numpy()

    @torch.inference_mode()
    def logits(self, observations: dict[str, dict[str, np.ndarray]]) -> torch.Tensor:
        """Action logits ``(R, 5)`` (``-inf`` for masked actions) from per-agent ego-graphs."""
        agents = list(observations)
        keys: tuple[str, ...] = GRAPH_KEYS[:-1]
        if self.model.config.time_horizon is not None:
            keys = (*keys, "steps_left")
        batch = {
            key: self._tensor(np.stack([_entry(observations, a, key) for a in agents]))
            for key in keys
        }
        return decentralized_logits(self.model, batch)

    def _tensor(self, array: np.ndarray) -> torch.Tensor:
        tensor = torch.from_numpy(array)
        return tensor.to(self._dtype) if tensor.is_floating_point() else tensor

    def act(self, observations: dict[str, dict[str, np.ndarray]]) -> dict[str, int]:
        """Each robot's action from its own ego-graph (decentralized)."""
        logits = self.logits(observations)
        if self.spread_margin is None:
            actions = self._choose(logits)
        else:
            views = [observations[a] for a in observations]
            actions = spread_actions(logits.numpy(), views, self.spread_margin)
        return dict(zip(observations, actions.tolist(), strict=True))

    @torch.inference_mode()
    def compact_logits(self, tables: CompactObservations) -> torch.Tensor:
        """Every robot's action logits ``(R, 5)`` from its own ego-graph, read from the
        compact tables (``env.observe_compact()``): the decentralized logits, batched without
        padding."""
        return compact_logits(self.model, tables, self._dtype)

    def act_compact(self, tables: CompactObservations) -> np.ndarray:
        """Every robot's action ``(R,)`` from the compact tables (decentralized)."""
        return self._choose(self.compact_logits(tables))

    @torch.inference_mode()
    def state_logits(self, state: dict[str, np.ndarray]) -> torch.Tensor:
        """Every robot's action logits ``(R, 5)`` from one pass over ``state()``."""
        tensors = {key: self._tensor(value) for key, value in state.items()}
        return centralized_logits(self.model, tensors)

    def _act_state(self, state: dict[str, np.ndarray]) -> np.ndarray:
        """Every robot's action ``(R,)`` from one pass over ``state()`` (centralized)."""
        return self._choose(self.state_logits(state))


def _entry(observations: dict[str, dict[str, np.ndarray]], agent: str, key: str) -> np.ndarray:
    """``observations[agent][key]``, or a ``KeyError`` that names both."""
    try:
        return observations[agent][key]
    except KeyError:
        raise KeyError(f"observation of agent {agent!r} has no {key!r}") from None
