"""Many coverage episodes stepped together, as a native TorchRL environment.

TorchRL's ``PettingZooWrapper`` works on :func:`marl_cover.parallel_env` but spends milliseconds
a step on per-agent spec handling. :class:`BatchedCoverageEnv` runs ``num_envs`` copies of the
same core (:meth:`marl_cover.CoverageEnv.apply_actions`, ``observe_batch`` and ``state``) and
returns stacked tensors, so its transitions are those of the PettingZoo environment, seed for
seed and action for action (tested).

Keys (``N`` = ``num_envs``, ``R`` = robots, ``M``/``E`` = padded ego-graph nodes/edges,
``M'``/``E'`` = padded state nodes/edges):

=====================================  ===============  ==========================================
key                                    shape            meaning
=====================================  ===============  ==========================================
``("robot", "observation", k)``        ``(N, R, ...)``  each robot's padded ego-graph, ``k`` in
                                                        ``nodes, node_pos, node_mask, edge_index,
                                                        edge_attr, edge_mask``, and its clock
                                                        ``steps_left (N, R)`` (omitted with
                                                        ``observe_robots=False``)
``("robot", "action_mask")``           ``(N, R, 5)``    bool, the robots' action masks
``("robot", "action")``                ``(N, R)``       int64 action in ``[0, 5)``
``("robot", "reward")``                ``(N, R, 1)``    the team reward (same for every robot)
``("robot", "info", k)``               ``(N, R)``       ``new_interest``, ``total_interest``
                                                        (int64), ``blocked``, ``invalid_action``
                                                        (bool), as the PettingZoo ``infos``
``("state", k)``                       ``(N, ...)``     ``state()``: the whole graph, ``k`` as
                                                        above plus ``robot_nodes (N, R)`` and
                                                        ``steps_left (N,)``
``done``, ``terminated``, ``truncated``  ``(N, 1)``     episode end (shared by the team)
=====================================  ===============  ==========================================

Seeding: after ``set_seed(s)``, the next reset of sub-environment ``i`` is
``CoverageEnv.reset(seed=s + i)`` and later resets continue that environment's generator, as
``reset()`` without a seed does in PettingZoo. Sub-environments that end are reset by TorchRL's
``_reset`` mask (collectors do it; ``rollout`` stops at the first end unless
``break_when_any_done=False``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Binary, Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from marl_cover.config import CoverageConfig
from marl_cover.ego import NUM_ACTIONS, NUM_NODE_FEATURES, PaddedShape
from marl_cover.env import CoverageEnv

#: Padded graph arrays of an observation (``action_mask`` is kept apart, as a bool).
GRAPH_ARRAYS = ("nodes", "node_pos", "node_mask", "edge_index", "edge_attr", "edge_mask")
#: Keys of ``("robot", "observation", k)``.
OBSERVATION_KEYS = (*GRAPH_ARRAYS, "steps_left")
#: Per-robot ``infos`` entries and their dtypes.
INFO_KEYS = {
    "new_interest": torch.int64,
    "total_interest": torch.int64,
    "blocked": torch.bool,
    "invalid_action": torch.bool,
}
#: Keys of ``("state", k)``.
STATE_KEYS = (*GRAPH_ARRAYS, "robot_nodes", "steps_left")
GROUP = "robot"


def graph_specs(shape: PaddedShape, lead: tuple[int, ...], device: Any) -> dict[str, Any]:
    """Specs of the padded graph arrays of :data:`GRAPH_ARRAYS` with leading dims ``lead``."""
    m, e = shape.max_nodes, shape.max_edges
    return {
        "nodes": Bounded(
            0.0, 1.0, shape=(*lead, m, NUM_NODE_FEATURES), dtype=torch.float32, device=device
        ),
        "node_pos": Unbounded(shape=(*lead, m, 2), dtype=torch.float32, device=device),
        "node_mask": Binary(shape=(*lead, m), device=device, dtype=torch.bool),
        "edge_index": Bounded(0, m - 1, shape=(*lead, 2, e), dtype=torch.int64, device=device),
        "edge_attr": Unbounded(shape=(*lead, e, 1), dtype=torch.float32, device=device),
        "edge_mask": Binary(shape=(*lead, e), device=device, dtype=torch.bool),
    }


class BatchedCoverageEnv(EnvBase):
    """``num_envs`` coverage episodes as one TorchRL environment (keys in the module docstring).

    Args:
        num_envs: Episodes stepped together (the batch size).
        config: Environment configuration; ``overrides`` replace its fields.
        observe_robots: Build every robot's ego-graph each step (off: only ``state`` and the
            action masks, for training loops whose actor reads ``state``).
        device: Where the output tensors live (the simulation runs on the CPU).
        **overrides: Fields of :class:`marl_cover.config.CoverageConfig`.
    """

    def __init__(
        self,
        num_envs: int = 8,
        config: CoverageConfig | None = None,
        *,
        observe_robots: bool = True,
        device: Any = "cpu",
        **overrides: Any,
    ) -> None:
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        super().__init__(device=device, batch_size=torch.Size([num_envs]))
        self.envs = [CoverageEnv(config, **overrides) for _ in range(num_envs)]
        self.config = self.envs[0].config
        self.observe_robots = observe_robots
        #: ``(robot, info)`` entries: dtype and the shape after ``(N, R)``.
        self._info: dict[str, tuple[torch.dtype, tuple[int, ...]]] = {
            key: (dtype, ()) for key, dtype in INFO_KEYS.items()
        }
        self.num_robots = self.config.num_robots
        self._pending_seeds: list[int | None] = [None] * num_envs
        self._last: dict[str, np.ndarray] = {}
        self._make_specs()

    @property
    def num_envs(self) -> int:
        """Episodes stepped together (the batch size)."""
        return len(self.envs)

    def _make_specs(self) -> None:
        n, r, device = self.num_envs, self.num_robots, self.device
        core = self.envs[0]
        group: dict[str, Any] = {
            "action_mask": Binary(
                n=NUM_ACTIONS, shape=(n, r, NUM_ACTIONS), dtype=torch.bool, device=device
            ),
            "info": Composite(
                {
                    key: (
                        Binary(shape=(n, r, *tail), dtype=dtype, device=device)
                        if dtype == torch.bool
                        else Unbounded(shape=(n, r, *tail), dtype=dtype, device=device)
                    )
                    for key, (dtype, tail) in self._info.items()
                },
                shape=(n, r),
            ),
        }
        if self.observe_robots:
            observation = graph_specs(core._ego_shape, (n, r), device)
            observation["steps_left"] = Bounded(
                0, core.config.max_steps, shape=(n, r), dtype=torch.int64, device=device
            )
            group["observation"] = Composite(observation, shape=(n, r))
        state = graph_specs(core._state_shape, (n,), device)
        state["robot_nodes"] = Bounded(
            0, core._state_shape.max_nodes - 1, shape=(n, r), dtype=torch.int64, device=device
        )
        state["steps_left"] = Bounded(
            0, core.config.max_steps, shape=(n,), dtype=torch.int64, device=device
        )
        graphs = {"state": Composite(state, shape=(n,))}
        self.observation_spec = Composite(
            {GROUP: Composite(group, shape=(n, r)), **graphs}, shape=(n,)
        )
        self.action_spec = Composite(
            {
                GROUP: Composite(
                    {
                        "action": Categorical(
                            NUM_ACTIONS, shape=(n, r), dtype=torch.int64, device=device
                        )
                    },
                    shape=(n, r),
                )
            },
            shape=(n,),
        )
        self.reward_spec = Composite(
            {
                GROUP: Composite(
                    {"reward": Unbounded(shape=(n, r, 1), dtype=torch.float32, device=device)},
                    shape=(n, r),
                )
            },
            shape=(n,),
        )
        self.done_spec = Composite(
            {
                key: Categorical(2, shape=(n, 1), dtype=torch.bool, device=device)
                for key in ("done", "terminated", "truncated")
            },
            shape=(n,),
        )

    # ------------------------------------------------------------------ EnvBase
    def _set_seed(self, seed: int | None) -> None:
        base = 0 if seed is None else int(seed)
        self._pending_seeds = [base + i for i in range(self.num_envs)]

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        if tensordict is not None and "_reset" in tensordict:
            rows = tensordict.get("_reset").reshape(self.num_envs).cpu().numpy().nonzero()[0]
        else:
            rows = np.arange(self.num_envs)
        if not self._last:
            rows = np.arange(self.num_envs)  # nothing to keep before the first reset
        fresh = {}
        for i in rows:
            seed, self._pending_seeds[i] = self._pending_seeds[i], None
            self.envs[i].reset(seed=seed)
            fresh[int(i)] = self._read(self.envs[i])
        out = self._merge(fresh, reset=True)
        zeros = np.zeros((self.num_envs, 1), dtype=bool)
        return self._to_tensordict(out, done=zeros, terminated=zeros, truncated=zeros)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get((GROUP, "action")).reshape(self.num_envs, -1).cpu().numpy()
        if action.shape[1] != self.num_robots:
            raise ValueError(
                f"({GROUP!r}, 'action') must hold {self.num_robots} actions per episode, got "
                f"shape {tuple(tensordict.get((GROUP, 'action')).shape)}"
            )
        if action.size and (action.min() < 0 or action.max() >= NUM_ACTIONS):
            raise ValueError(f"actions must lie in [0, {NUM_ACTIONS}), got {action.tolist()}")
        rows = {}
        reward = np.zeros((self.num_envs, self.num_robots, 1), dtype=np.float32)
        terminated = np.zeros((self.num_envs, 1), dtype=bool)
        truncated = np.zeros((self.num_envs, 1), dtype=bool)
        for i, env in enumerate(self.envs):
            if not env.agents:
                raise RuntimeError(
                    f"episode {i} of the batch is over; reset it (the '_reset' mask) before "
                    "stepping"
                )
            moves = env.apply_actions(action[i].astype(np.int64))
            reward[i] = float(moves.new_interest.sum())
            terminated[i], truncated[i] = moves.terminated, moves.truncated
            info = {
                "new_interest": moves.new_interest,
                "total_interest": env.credits,
                "blocked": moves.blocked,
                "invalid_action": moves.invalid,
            }
            rows[i] = {**self._read(env), **{f"info.{k}": v for k, v in info.items()}}
        out = self._merge(rows, reset=False)
        done = terminated | truncated
        result = self._to_tensordict(out, done=done, terminated=terminated, truncated=truncated)
        result.set((GROUP, "reward"), torch.from_numpy(reward).to(self.device))
        return result

    # ------------------------------------------------------------------ arrays
    def _read(self, env: CoverageEnv) -> dict[str, np.ndarray]:
        """One episode's observation arrays, flat keys (``obs.k``, ``state.k``, ...)."""
        state = env.state()
        row = {f"state.{k}": state[k] for k in STATE_KEYS}
        row["action_mask"] = state["action_mask"].astype(bool)
        if self.observe_robots:
            ego = env.observe_batch()
            row.update({f"obs.{k}": ego[k] for k in OBSERVATION_KEYS})
        return row

    def _merge(self, rows: dict[int, dict[str, np.ndarray]], reset: bool) -> dict[str, np.ndarray]:
        """Stacks every episode's arrays; episodes without a new row keep their last ones, and
        the keys a new row lacks (the infos, after a reset) read 0."""
        if len(rows) == self.num_envs:
            out = {k: np.stack([rows[i][k] for i in range(self.num_envs)]) for k in rows[0]}
        else:
            out = {}
            for key, last in self._last.items():
                array = last.copy()
                for i, row in rows.items():
                    array[i] = row.get(key, 0)
                out[key] = array
        if reset:  # the infos of a fresh episode are zeros (kept rows were zeroed above)
            for key, (dtype, tail) in self._info.items():
                if f"info.{key}" not in out:
                    zeros = torch.zeros((self.num_envs, self.num_robots, *tail), dtype=dtype)
                    out[f"info.{key}"] = zeros.numpy()
        self._last = out
        return out

    def _to_tensordict(self, out: dict[str, np.ndarray], **done: np.ndarray) -> TensorDictBase:
        n, r = self.num_envs, self.num_robots
        group = TensorDict(
            {
                "action_mask": torch.from_numpy(out["action_mask"]),
                "info": TensorDict(
                    {k: torch.from_numpy(out[f"info.{k}"]) for k in self._info},
                    batch_size=(n, r),
                ),
            },
            batch_size=(n, r),
        )
        if self.observe_robots:
            group["observation"] = TensorDict(
                {k: torch.from_numpy(out[f"obs.{k}"]) for k in OBSERVATION_KEYS},
                batch_size=(n, r),
            )
        state = TensorDict(
            {k: torch.from_numpy(out[f"state.{k}"]) for k in STATE_KEYS},
            batch_size=(n,),
        )
        graphs = {"state": state}
        result = TensorDict(
            {GROUP: group, **graphs, **{k: torch.from_numpy(v) for k, v in done.items()}},
            batch_size=(n,),
        )
        return result.to(self.device) if self.device != torch.device("cpu") else result
