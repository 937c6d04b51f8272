"""The pieces of a MAPPO run: the batched environment, the actor, the critic, the PPO loss,
and the batch preparation (per-robot rewards and episode ends)."""

from __future__ import annotations

from typing import Any

import torch

from marl_cover.agents.models.actors import make_actor, make_state_actor
from marl_cover.agents.models.gnn import AggregationGNN
from marl_cover.agents.models.value import EgoValue, StateValue
from marl_cover.agents.training.mappo_config import REWARDS, MAPPOConfig

GROUP = "robot"
GRAPH_IN = ("nodes", "edge_index", "edge_attr", "edge_mask", "node_mask")


def resolve_device(name: str) -> torch.device:
    """``"auto"``: CUDA where available, else the CPU; any other name as ``torch.device``.

    Raises:
        ValueError: ``"cuda"`` asked for on a machine without a usable GPU.
    """
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    device = torch.device(name)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device={name} but torch sees no CUDA GPU here (use device=cpu or auto)")
    return device


def make_env(config: MAPPOConfig) -> Any:
    """The batched TorchRL environment of a run."""
    from marl_cover.agents.training.batched_env import BatchedCoverageEnv

    return BatchedCoverageEnv(
        config.collector.num_envs, observe_robots=config.needs_ego, **config.env.as_kwargs()
    )


def build_actor(gnn: AggregationGNN, config: MAPPOConfig, num_robots: int) -> Any:
    """The ``ProbabilisticActor`` on the batched environment's keys."""
    temperature = config.model.temperature
    if config.model.actor_input == "state":
        return make_state_actor(gnn, num_robots, temperature=temperature)
    return make_actor(
        gnn,
        observation_key=(GROUP, "observation"),
        action_key=(GROUP, "action"),
        mask_key=(GROUP, "action_mask"),
        temperature=temperature,
    )


def build_critic(gnn: AggregationGNN, config: MAPPOConfig, num_robots: int) -> Any:
    """The value module writing ``(robot, state_value)``."""
    from tensordict.nn import TensorDictModule

    if config.algorithm == "ippo":
        return TensorDictModule(
            EgoValue(gnn),
            in_keys=[(GROUP, "observation", k) for k in GRAPH_IN],
            out_keys=[(GROUP, "state_value")],
        )
    return TensorDictModule(
        StateValue(gnn, num_robots, config.model.value_aggregate),
        in_keys=[("state", k) for k in GRAPH_IN],
        out_keys=[(GROUP, "state_value")],
    )


def build_loss(actor: Any, critic: Any, config: MAPPOConfig) -> Any:
    """``ClipPPOLoss`` with a GAE estimator on the group's keys."""
    from torchrl.objectives import ClipPPOLoss, ValueEstimators

    loss = ClipPPOLoss(
        actor_network=actor,
        critic_network=critic,
        clip_epsilon=config.loss.clip_epsilon,
        entropy_coeff=config.loss.entropy_coef,
        critic_coeff=config.loss.critic_coef,
        normalize_advantage=config.loss.normalize_advantage,
        normalize_advantage_exclude_dims=(-2,),  # per robot
    )
    loss.set_keys(
        reward=(GROUP, "reward"),
        action=(GROUP, "action"),
        sample_log_prob=(GROUP, "sample_log_prob"),
        value=(GROUP, "state_value"),
        done=(GROUP, "done"),
        terminated=(GROUP, "terminated"),
    )
    loss.make_value_estimator(  # the critic reads data-dependent sizes: no vmap
        ValueEstimators.GAE, gamma=config.loss.gamma, lmbda=config.loss.lmbda, deactivate_vmap=True
    )
    return loss


def prepare_batch(data: Any, reward_scale: float, reward: str = "team") -> Any:
    """Sets the reward each robot learns from (the team reward, or with ``reward="own"`` its
    own newly visited points of interest) times ``reward_scale``, and copies the episode ends
    onto every robot (GAE reads them beside the per-robot rewards), in place."""
    if reward not in REWARDS:
        raise ValueError(f"reward must be one of {REWARDS}, got {reward!r}")
    team = data.get(("next", GROUP, "reward"))  # (..., R, 1)
    if reward == "own":
        own = data.get(("next", GROUP, "info", "new_interest")).unsqueeze(-1)
        team = own.to(team.dtype)
    for key, source in (("done", "done"), ("terminated", "terminated")):
        data.set(("next", GROUP, key), data.get(("next", source)).unsqueeze(-2).expand(team.shape))
    data.set(("next", GROUP, "reward"), team * reward_scale)
    return data


def episode_rewards(data: Any) -> list[float]:
    """Team rewards of the episodes that ended in a batch (the robots' credits at the end)."""
    done = data.get(("next", "done")).squeeze(-1)
    totals = data.get(("next", GROUP, "info", "total_interest")).sum(-1)
    return totals[done].float().tolist()
