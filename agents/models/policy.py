"""The GNN as a policy: TensorDict modules for training loops, an evaluation policy, checkpoints.

- :class:`EgoGraphLogits` maps padded ego-graph observations (any leading batch shape, such as
  ``(robots,)`` or ``(envs, robots)``) to action logits and a boolean action mask;
  :func:`make_actor` wraps it as a TorchRL ``ProbabilisticActor`` with a ``MaskedCategorical``
  (the module that behaviour cloning and MAPPO share). :class:`StateLogits` /
  :func:`make_state_actor` give every robot's logits from one pass over each whole-graph state
  (the same numbers, for the training loops).
- :class:`GNNPolicy` plays in the evaluation harness: decentralized (each robot on its own
  ego-graph, :meth:`GNNPolicy.act`) or centralized (one pass on ``state()``,
  :meth:`GNNPolicy.act_state`), greedy (argmax) by default.
- :func:`save_model` / :func:`load_model`: a model file carries its :class:`GNNConfig` and any
  metadata (command, seed, dataset), written atomically.
"""

from __future__ import annotations

import io
import pickle
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from agents.cli import write_bytes_atomic
from agents.models.gnn import (
    AggregationGNN,
    GNNConfig,
    batched_state_logits,
    centralized_logits,
    decentralized_logits,
)
from agents.spread import spread_actions
from marl_cover.ego import NUM_ACTIONS

#: Keys of a padded graph observation read by the policy.
GRAPH_KEYS = ("nodes", "edge_index", "edge_attr", "edge_mask", "action_mask")


class StateLogits(nn.Module):
    """Action logits ``(..., R, 5)`` and mask ``(..., R, 5)`` bool of every robot from padded
    states ``(..., M, *)`` (whose first ``5 R`` edges are the robots' action edges).

    One pass over each state gives every robot's logits: the same numbers as
    :class:`EgoGraphLogits` on the robots' ego-graphs (the ego-graph holds the network's whole
    receptive field), for about ``1 / R`` of the work; training loops use it. Masked actions
    get logit 0 (finite, so that entropies and gradients stay clean); the mask output is what a
    ``MaskedCategorical`` must read.
    """

    def __init__(self, gnn: AggregationGNN, num_robots: int) -> None:
        super().__init__()
        self.gnn = gnn
        self.num_robots = num_robots

    def forward(
        self,
        nodes: torch.Tensor,
        edge_index: torch.Tensor,
        edge_attr: torch.Tensor,
        edge_mask: torch.Tensor,
        node_mask: torch.Tensor | None,
        action_mask: torch.Tensor,
        steps_left: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Logits and mask ``(..., R, 5)`` of padded states ``(..., M, *)`` (class docstring)."""
        lead, r = nodes.shape[:-2], self.num_robots
        batch = flat_batch(nodes, edge_index, edge_attr, edge_mask, node_mask)
        if steps_left is not None:  # (*lead,): read when the network has a time_horizon
            batch["steps_left"] = steps_left.reshape(-1)
        logits = batched_state_logits(self.gnn, batch, r)  # (B, R, 5), -inf without an edge
        mask = action_mask.reshape(-1, r, NUM_ACTIONS).bool() & torch.isfinite(logits)
        logits = logits.masked_fill(~mask, 0.0)
        return logits.view(*lead, r, NUM_ACTIONS), mask.view(*lead, r, NUM_ACTIONS)


class EgoGraphLogits(StateLogits):
    """Action logits ``(..., 5)`` and mask ``(..., 5)`` bool of each ego robot from its padded
    ego-graph ``(..., M, *)``: an ego-graph is laid out as a state with one robot, the ego."""

    def __init__(self, gnn: AggregationGNN) -> None:
        super().__init__(gnn, num_robots=1)

    def forward(  # type: ignore[override]
        self,
        nodes: torch.Tensor,
        edge_index: torch.Tensor,
        edge_attr: torch.Tensor,
        edge_mask: torch.Tensor,
        action_mask: torch.Tensor,
        steps_left: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Logits and mask ``(..., 5)`` of padded ego-graphs ``(..., M, *)``."""
        logits, mask = super().forward(
            nodes, edge_index, edge_attr, edge_mask, None, action_mask.unsqueeze(-2), steps_left
        )
        return logits.squeeze(-2), mask.squeeze(-2)


def flat_batch(
    nodes: torch.Tensor,
    edge_index: torch.Tensor,
    edge_attr: torch.Tensor,
    edge_mask: torch.Tensor,
    node_mask: torch.Tensor | None = None,
) -> dict[str, torch.Tensor]:
    """Padded graph arrays with any leading shape as one batch axis (the input of
    :func:`~agents.models.gnn.flatten_padded`)."""
    batch = {
        "nodes": nodes.reshape(-1, *nodes.shape[-2:]),
        "edge_index": edge_index.reshape(-1, *edge_index.shape[-2:]),
        "edge_attr": edge_attr.reshape(-1, *edge_attr.shape[-2:]),
        "edge_mask": edge_mask.reshape(-1, edge_mask.shape[-1]),
    }
    if node_mask is not None:
        batch["node_mask"] = node_mask.reshape(-1, node_mask.shape[-1])
    return batch


class Tempered(nn.Module):
    """A ``(logits, mask)`` module with its logits divided by ``temperature`` (below 1: a
    sharper sampling policy with the same argmax)."""

    def __init__(self, module: nn.Module, temperature: float) -> None:
        super().__init__()
        if temperature <= 0:
            raise ValueError(f"temperature must be > 0, got {temperature}")
        self.module = module
        self.temperature = temperature

    def forward(self, *inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The wrapped module's logits divided by the temperature, and its mask."""
        logits, mask = self.module(*inputs)
        return logits / self.temperature, mask


def make_actor(
    gnn: AggregationGNN,
    observation_key: Any = "observation",
    action_key: Any = "action",
    mask_key: Any = None,
    temperature: float = 1.0,
) -> Any:
    """A TorchRL ``ProbabilisticActor`` over ``EgoGraphLogits`` with a ``MaskedCategorical``.

    Args:
        gnn: The shared network.
        observation_key: Key (or nested key, e.g. ``("robot", "observation")``) under which the
            padded ego-graph entries (:data:`GRAPH_KEYS`) live.
        action_key: Where the sampled action goes; logits, mask and log-probability are written
            beside it (``"logits"``, ``"mask"``, ``"sample_log_prob"`` under the same prefix).
        mask_key: Where the action mask is read (default: ``action_mask`` inside the
            observation; TorchRL's ``PettingZooWrapper`` lifts it to ``(group, "action_mask")``).
        temperature: Divides the logits of the sampling policy (see :class:`Tempered`).

    A network with a ``time_horizon`` also reads ``steps_left`` inside the observation.
    """
    prefix = observation_key if isinstance(observation_key, tuple) else (observation_key,)
    in_keys = [(*prefix, key) for key in GRAPH_KEYS[:-1]]
    in_keys.append(mask_key if mask_key is not None else (*prefix, "action_mask"))
    if gnn.config.time_horizon is not None:
        in_keys.append((*prefix, "steps_left"))
    return _masked_actor(EgoGraphLogits(gnn), in_keys, action_key, temperature)


def make_state_actor(
    gnn: AggregationGNN,
    num_robots: int,
    state_key: Any = "state",
    action_key: Any = ("robot", "action"),
    mask_key: Any = ("robot", "action_mask"),
    temperature: float = 1.0,
) -> Any:
    """A ``ProbabilisticActor`` of every robot at once over :class:`StateLogits` (the keys of
    :class:`agents.batched_env.BatchedCoverageEnv` by default; ``temperature`` as in
    :func:`make_actor`; a network with a ``time_horizon`` also reads the state's
    ``steps_left``)."""
    prefix = state_key if isinstance(state_key, tuple) else (state_key,)
    in_keys = [(*prefix, key) for key in (*GRAPH_KEYS[:-1], "node_mask")]
    in_keys.append(mask_key)
    if gnn.config.time_horizon is not None:
        in_keys.append((*prefix, "steps_left"))
    module = StateLogits(gnn, num_robots)
    return _masked_actor(module, in_keys, action_key, temperature)


def _masked_actor(
    logits_module: nn.Module, in_keys: list[Any], action_key: Any, temperature: float = 1.0
) -> Any:
    """A ``ProbabilisticActor`` with a ``MaskedCategorical`` over a module returning
    ``(logits, mask)``; logits, mask and log-probability are written beside ``action_key``."""
    from tensordict.nn import TensorDictModule
    from torchrl.modules import MaskedCategorical, ProbabilisticActor

    def beside(name: str) -> Any:
        return (*action_key[:-1], name) if isinstance(action_key, tuple) else name

    if temperature != 1.0:
        logits_module = Tempered(logits_module, temperature)
    module = TensorDictModule(
        logits_module, in_keys=in_keys, out_keys=[beside("logits"), beside("mask")]
    )
    return ProbabilisticActor(
        module,
        in_keys={"logits": beside("logits"), "mask": beside("mask")},
        out_keys=[action_key],
        distribution_class=MaskedCategorical,
        return_log_prob=True,
        log_prob_key=beside("sample_log_prob"),
    )


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
            ego-graph (:mod:`agents.spread`); ``None``: the plain argmax. Decentralized and
            deterministic only.

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
    def state_logits(self, state: dict[str, np.ndarray]) -> torch.Tensor:
        """Every robot's action logits ``(R, 5)`` from one pass over ``state()``."""
        tensors = {key: self._tensor(value) for key, value in state.items()}
        return centralized_logits(self.model, tensors)

    def _act_state(self, state: dict[str, np.ndarray]) -> np.ndarray:
        """Every robot's action ``(R,)`` from one pass over ``state()`` (centralized)."""
        return self._choose(self.state_logits(state))


class EnsemblePolicy(GNNPolicy):
    """Several GNNs playing as one: every robot scores an action by the mean of the members'
    log-probabilities (the normalised product of their distributions) and takes the best.

    A teacher for distillation (``dagger.expert_mode=gnn`` in behaviour cloning) more than a
    controller: it costs the sum of its members' time.

    Args:
        models: The members (any configs; they see the same observations).
        centralized, deterministic, seed, temperature, spread_margin: As for
            :class:`GNNPolicy` (the spread rule reads the pooled logits).

    Raises:
        ValueError: no member.
    """

    def __init__(
        self,
        models: list[AggregationGNN],
        centralized: bool = False,
        deterministic: bool = True,
        seed: int = 0,
        temperature: float = 1.0,
        spread_margin: float | None = None,
    ) -> None:
        if not models:
            raise ValueError("an ensemble needs at least one model")
        super().__init__(models[0], centralized, deterministic, seed, temperature, spread_margin)
        self.members = [GNNPolicy(model) for model in models]

    def logits(self, observations: dict[str, dict[str, np.ndarray]]) -> torch.Tensor:
        """The members' pooled logits ``(R, 5)`` from per-agent ego-graphs."""
        return _pooled([member.logits(observations) for member in self.members])

    def state_logits(self, state: dict[str, np.ndarray]) -> torch.Tensor:
        """The members' pooled logits ``(R, 5)`` from one ``state()``."""
        return _pooled([member.state_logits(state) for member in self.members])


def _pooled(logits: list[torch.Tensor]) -> torch.Tensor:
    """The mean of log-softmaxed logits ``(R, 5)`` (masked actions stay ``-inf``)."""
    return torch.stack([torch.log_softmax(x.double(), dim=-1) for x in logits]).mean(dim=0)


def _entry(observations: dict[str, dict[str, np.ndarray]], agent: str, key: str) -> np.ndarray:
    """``observations[agent][key]``, or a ``KeyError`` that names both."""
    try:
        return observations[agent][key]
    except KeyError:
        raise KeyError(f"observation of agent {agent!r} has no {key!r}") from None


def save_model(
    path: str | Path, model: AggregationGNN, metadata: dict[str, Any], **extra: Any
) -> None:
    """Writes ``model`` with its config and ``metadata`` to ``path`` atomically.

    ``extra`` entries (a training checkpoint's optimiser, sampler, ...) are stored beside them;
    :func:`load_model` ignores them.
    """
    buffer = io.BytesIO()
    record = {"gnn_config": asdict(model.config), "state_dict": model.state_dict()}
    torch.save({**record, "metadata": metadata, **extra}, buffer)
    write_bytes_atomic(path, buffer.getvalue())


def load_model(path: str | Path) -> tuple[AggregationGNN, dict[str, Any]]:
    """The network saved at ``path`` (by :func:`save_model` or a training checkpoint).

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: the file is not a model file, naming it and the missing key.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no model file at {path}")
    try:
        record = torch.load(path, map_location="cpu", weights_only=False)
    except (pickle.UnpicklingError, EOFError, RuntimeError) as error:  # not a torch file
        raise ValueError(f"{path} is not a model file ({type(error).__name__}: {error})") from None
    for key in ("gnn_config", "state_dict"):
        if not isinstance(record, dict) or key not in record:
            raise ValueError(f"{path} is not a model file (no {key!r} entry)")
    model = AggregationGNN(GNNConfig(**record["gnn_config"]))
    model.load_state_dict(record["state_dict"])
    return model.eval(), dict(record.get("metadata", {}))


def average_models(paths: list[str | Path]) -> tuple[AggregationGNN, dict[str, Any]]:
    """The parameter-wise mean of the networks saved at ``paths`` (a "model soup").

    Meant for models fine-tuned from one start, whose weights stay close; the metadata is the
    first file's, with ``"average_of"`` listing every file.

    Raises:
        ValueError: fewer than two files, or a file whose network has another config than the
            first's, naming it.
    """
    if len(paths) < 2:
        raise ValueError(f"averaging needs at least two model files, got {len(paths)}")
    models, metadata = _load_alike(paths)
    average = AggregationGNN(models[0].config)
    states = [model.state_dict() for model in models]
    average.load_state_dict(
        {key: torch.stack([state[key] for state in states]).mean(dim=0) for key in states[0]}
    )
    return average.eval(), {**metadata, "average_of": [str(p) for p in paths]}


def merge_models(paths: list[str | Path]) -> tuple[AggregationGNN, dict[str, Any]]:
    """The networks saved at ``paths`` as one ensemble network
    (:meth:`AggregationGNN.merged`: the mean of their logits in one pass); its metadata is
    ``{"merged_of": [the files]}``.

    Raises:
        ValueError: no file, or a file whose network has another config than the first's,
            naming it.
    """
    if not paths:
        raise ValueError("merging needs at least one model file")
    models, _ = _load_alike(paths)
    return AggregationGNN.merged(models).eval(), {"merged_of": [str(p) for p in paths]}


def _load_alike(paths: list[str | Path]) -> tuple[list[AggregationGNN], dict[str, Any]]:
    """The networks at ``paths`` and the first one's metadata; a ``ValueError`` names a file
    whose network has another config than the first's."""
    (first, metadata), *others = [load_model(path) for path in paths]
    for path, (model, _) in zip(paths[1:], others, strict=True):
        if model.config != first.config:
            raise ValueError(
                f"{path} holds a {model.config} network, not the {first.config} of {paths[0]}"
            )
    return [first, *(model for model, _ in others)], metadata
