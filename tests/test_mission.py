"""Missions: discrete policies driving the quadrotor environment, and scripts/run_mission.py."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers import run_cli

from marl_cover.agents.baselines.greedy import CentralizedGreedyPolicy, GreedyPolicy
from marl_cover.agents.experts.expert import RoutingExpert
from marl_cover.agents.mission.flight import (
    MissionConfig,
    MissionExpert,
    make_mission_policy,
    run_mission,
)
from marl_cover.continuous import QuadrotorCoverageEnv

ROOT = Path(__file__).resolve().parent.parent
SMALL = {"map": "city", "num_robots": 3, "city_size": 80, "hops": 6}


def small_env(max_time: float = 60.0, **dynamics) -> QuadrotorCoverageEnv:
    return QuadrotorCoverageEnv(dynamics={"max_time": max_time, **dynamics}, **SMALL)


def test_mission_curve_counts_the_rewards() -> None:
    env = small_env()
    result = run_mission(env, GreedyPolicy(6), seed=3)
    curve = np.array(result.visited)
    assert curve.shape == (61,) and curve[0] == 0
    assert np.all(np.diff(curve) >= 0) and curve[-1] == result.total
    snapshot = env.snapshot()
    starts = env.config.num_robots  # start waypoints are visited without reward
    assert (
        result.total <= int((snapshot.interest & snapshot.visited).sum()) <= result.total + starts
    )
    assert result.mission_seconds == pytest.approx(60.0)
    assert result.decisions <= result.steps


def test_cached_decisions_give_the_same_mission() -> None:
    """Asking a deterministic policy again when nothing it sees has changed is skipped; an
    uncached run (greedy behind act_env, which is never cached) flies the same mission."""

    class Uncached:
        def __init__(self) -> None:
            self.policy = CentralizedGreedyPolicy(6)

        def act_env(self, env: QuadrotorCoverageEnv) -> dict[str, int]:
            actions = self.policy.act_state(env.state())
            return dict(zip(env.possible_agents, actions.tolist(), strict=True))

    cached = run_mission(small_env(retarget="rate"), CentralizedGreedyPolicy(6), seed=1)
    uncached = run_mission(small_env(retarget="rate"), Uncached(), seed=1)
    assert cached.visited == uncached.visited
    assert cached.decisions < uncached.decisions == uncached.steps


def test_expert_follows_its_route_on_a_line(path_graph) -> None:
    env = QuadrotorCoverageEnv(graph=path_graph, num_robots=1, dynamics={"max_time": 60.0})
    expert = MissionExpert(RoutingExpert(max_iterations=50))
    options = {"robot_nodes": [2], "interest_nodes": [0, 6]}
    env.reset(seed=0, options=options)
    visits = []
    while env.agents:
        _, rewards, *_ = env.step(expert.act_env(env))
        if rewards["robot_0"]:
            visits.append((round(env.time, 1), int(env.targets[0])))
    # Nearer end first (2 hops west), then 6 hops east; done long before 60 s.
    assert [node for _, node in visits] == [0, 6]
    assert visits[-1][0] < 40.0
    assert expert.counts["solves"] == 1


@pytest.mark.parametrize("retarget", ["arrival", "rate"])
def test_golden_greedy_mission(retarget: str) -> None:
    env = small_env(retarget=retarget, altitude_range=(5.0, 5.0))  # one altitude for all
    result = run_mission(env, GreedyPolicy(6), seed=0)
    curve = result.visited
    observed = (result.total, result.steps, curve[10], curve[20], curve[40], result.near_misses)
    assert observed == GOLDEN[retarget]


# (total, steps, visited by 10 s, 20 s, 40 s, near-misses): flying on without stopping at
# waypoints ("rate") visits sooner; greedy never crosses another robot here.
GOLDEN = {"arrival": (23, 266, 6, 12, 20, 0), "rate": (23, 600, 7, 14, 21, 0)}


def test_mission_config_rejects_unknown_methods_and_keys() -> None:
    with pytest.raises(ValueError, match="unknown mission method.*'gnn2'"):
        MissionConfig(methods=["gnn2"])
    from marl_cover.agents.cli.options import load

    with pytest.raises(ValueError, match="Key 'speed' not in"):
        load(MissionConfig, None, ["dynamics.quadrotor.speed=3"])
    config = load(MissionConfig, "mission", ["dynamics.retarget=rate"])
    assert config.dynamics.retarget == "rate" and config.dynamics.quadrotor.mass == 0.71
    assert isinstance(make_mission_policy("greedy", config), GreedyPolicy)
    assert load(MissionConfig, None, ["animate_seed=null"]).animate_seed is None
    for key, value in (("animate_seed", -1), ("seeds", 0), ("seed", -2), ("num_robots", 0)):
        with pytest.raises(ValueError, match=f"mission {key} must be >= .*got {value}"):
            load(MissionConfig, None, [f"{key}={value}"])
    with pytest.raises(ValueError, match="frame_every must be > 0"):
        MissionConfig(frame_every=0.0)
    with pytest.raises(ValueError, match=r"no model file at nowhere.pt and no shipped model"):
        load(MissionConfig, None, ["model=nowhere.pt"])
    assert load(MissionConfig, None, ["model=nowhere.pt", "methods=[greedy]"]).methods == [
        "greedy"
    ]  # a model file only matters to the GNN
    for bad in (["gnn_spread=-0.5"], ["gnn_spread=0.5", "gnn_centralized=true"]):
        with pytest.raises(ValueError, match="gnn_spread must be >= 0 and needs gnn_central"):
            load(MissionConfig, None, bad)
    spread = load(MissionConfig, "mission", ["gnn_spread=0.5"])
    assert make_mission_policy("gnn", spread).spread_margin == 0.5
    assert spread.setup("gnn")["gnn_spread"] == 0.5  # a resumed run tells the decoding apart
    assert "gnn_spread" not in config.setup("gnn")  # setups recorded before it still match
    for bad in (
        ["gnn_rollout=-1"],
        ["gnn_rollout=1", "gnn_rollout_horizon=0"],
        ["gnn_rollout=1", "gnn_centralized=true"],
        ["gnn_rollout=1", "gnn_spread=0.5"],
        ["gnn_rollout=1", "gnn_rollout_greedy_after=-1"],
    ):
        with pytest.raises(ValueError, match="gnn_rollout must be >= 0 with gnn_rollout_hor"):
            load(MissionConfig, None, bad)
    planned = load(MissionConfig, "mission", ["gnn_rollout=1.5"])
    policy = make_mission_policy("gnn", planned)
    assert (policy.margin, policy.horizon) == (1.5, 20)
    assert planned.setup("gnn")["gnn_rollout"] == 1.5
    assert planned.setup("gnn")["gnn_rollout_horizon"] == 20
    assert "gnn_rollout" not in config.setup("gnn")
    assert "gnn_rollout_greedy_after" not in planned.setup("gnn")  # earlier setups match
    on_greedy = load(MissionConfig, None, ["gnn_rollout=1", "gnn_rollout_greedy_after=2"])
    assert make_mission_policy("gnn", on_greedy).greedy_after == 2
    assert on_greedy.setup("gnn")["gnn_rollout_greedy_after"] == 2


def test_ego_graphs_span_the_gnn_receptive_field(tmp_path: Path) -> None:
    """A GNN that sees farther than greedy's ``hops`` gets ego-graphs of its own radius, and
    greedy flies the same mission on them (it counts only the points within its ``hops``)."""
    import torch

    from marl_cover.agents.models.checkpoints import save_model
    from marl_cover.agents.models.gnn import AggregationGNN, GNNConfig

    torch.manual_seed(0)
    path = tmp_path / "far.pt"
    save_model(path, AggregationGNN(GNNConfig(hops=9, hidden=4)), {})
    config = MissionConfig(hops=6, model=str(path), methods=["greedy", "gnn"])
    assert config.observation_hops() == 9
    assert MissionConfig(hops=6, model=str(path), methods=["greedy"]).observation_hops() == 6
    assert MissionConfig(hops=6, model=str(path), gnn_centralized=True).observation_hops() == 6
    assert MissionConfig(hops=12, model=str(path)).observation_hops() == 12
    near = run_mission(small_env(), GreedyPolicy(6, fallback="stay"), seed=2)
    wide = QuadrotorCoverageEnv(dynamics={"max_time": 60.0}, **{**SMALL, "hops": 9})
    far = run_mission(wide, GreedyPolicy(6, fallback="stay"), seed=2)
    assert far.visited == near.visited and far.total > 0


def test_run_mission_script(tmp_path: Path) -> None:
    out = tmp_path / "mission"
    args = [
        "map=city",
        "num_robots=3",
        "hops=6",
        "seeds=2",
        "methods=[greedy,gnn]",
        "dynamics.max_time=15.0",
        f"out={out}",
        "frame_every=3.0",
    ]
    done = run_cli("mission", *args)
    assert done.returncode == 0, done.stderr[-2000:]
    summary = json.loads((out / "mission.json").read_text())
    assert set(summary["methods"]) == {"greedy", "gnn"} and summary["seeds"] == [0, 1]
    runs = [json.loads((out / "runs" / f"gnn_{s}.json").read_text()) for s in (0, 1)]
    assert summary["methods"]["gnn"]["totals"] == [r["total"] for r in runs]
    assert (out / "mission.png").stat().st_size > 0
    assert (out / "mission_gnn.gif").read_bytes()[:3] == b"GIF"
    # A second run reads the missions back instead of flying them again.
    again = run_cli("mission", *args)
    assert again.returncode == 0 and "seed" not in again.stdout.split("points of interest")[0]
    # Another model under the same out= folder is an error that names the run and the change.
    other = args + ["model=gnn_mappo"]
    refused = run_cli("mission", *other)
    assert refused.returncode != 0 and "Traceback" not in refused.stderr
    assert "gnn_0.json: made under another setup" in refused.stderr
    assert "model_sha256" in refused.stderr
    # A bad override ends the script with one line naming it, before anything flies.
    bad = run_cli("mission", *args, "seeds=ten")
    assert bad.returncode != 0 and "Traceback" not in bad.stderr
    assert "Value 'ten' of type 'str' could not be converted to Integer" in bad.stderr
    assert bad.stderr.strip().endswith("(full_key: seeds)")


def test_bench_mission_reports_each_flight(tmp_path: Path) -> None:
    """The speed benchmark's JSON: one row per flight, each factor its simulated seconds over its
    wall seconds, and the slowest per method; the missions are those of ``run_mission``."""
    out = tmp_path / "bench.json"
    args = ["map=city", "num_robots=3", "dynamics.max_time=20"]
    done = run_cli(
        "bench-mission",
        "methods=[greedy]",
        "seeds=[0,1]",
        f"out={out}",
        *(f"mission.{arg}" for arg in args),
    )
    assert done.returncode == 0, done.stderr
    report = json.loads(out.read_text())
    rows = report["rows"]
    assert [(r["method"], r["seed"]) for r in rows] == [("greedy", 0), ("greedy", 1)]
    for row in rows:
        assert row["real_time_factor"] == pytest.approx(
            row["mission_seconds"] / row["wall_seconds"]
        )
        assert 0 < row["policy_seconds"] < row["wall_seconds"]
    assert report["min_real_time_factor"] == {"greedy": min(r["real_time_factor"] for r in rows)}
    from marl_cover.agents.cli.options import load

    config = load(MissionConfig, "mission", args)
    flown = run_mission(config.make_env(), make_mission_policy("greedy", config), 1)
    assert (flown.mission_seconds, flown.decisions) == (
        rows[1]["mission_seconds"],
        rows[1]["decisions"],
    )


def test_the_decentralized_rollout_flies_the_mission() -> None:
    """On the quadrotors the rollout plans on each ready robot's ego-graph: margin 0 flies the
    GNN's mission, a wide margin plays moves out (``steps_left`` is the nominal
    clock) and changes some of them."""
    import torch

    from marl_cover.agents.models.gnn import AggregationGNN, GNNConfig
    from marl_cover.agents.models.policy import GNNPolicy
    from marl_cover.agents.planners.local_rollout import LocalRolloutPolicy

    torch.manual_seed(0)
    model = AggregationGNN(GNNConfig(hops=6, hidden=8))
    plain = run_mission(small_env(30.0), GNNPolicy(model), seed=4)
    tied = run_mission(small_env(30.0), LocalRolloutPolicy(model, margin=0.0), seed=4)
    # exact ties are played out too (one here), and none of them changed a move
    assert tied.visited == plain.visited and "changed" not in tied.policy_counts
    wide = run_mission(small_env(30.0), LocalRolloutPolicy(model, margin=100.0, horizon=3), seed=4)
    assert wide.policy_counts["played"] > 0 and wide.policy_counts["changed"] > 0
    greedy = LocalRolloutPolicy(model, margin=100.0, horizon=3, greedy_after=0)
    on_greedy = run_mission(small_env(30.0), greedy, seed=4)
    assert on_greedy.policy_counts["played"] == wide.policy_counts["played"]
    assert on_greedy.visited != wide.visited  # other play-outs, other choices
