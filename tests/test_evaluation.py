"""The evaluation harness and its command line."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from helpers import run_cli

import marl_cover
from marl_cover.agents.baselines.greedy import CentralizedGreedyPolicy, GreedyPolicy
from marl_cover.agents.evaluation.episodes import EpisodeResult, evaluate, summarize


def test_summary_statistics() -> None:
    results = [EpisodeResult(s, r, 0.5, 10, 0.01, 0.02) for s, r in enumerate([2.0, 4.0, 6.0])]
    summary = summarize(results)
    assert summary.mean == 4.0 and summary.std == 2.0
    assert summary.sem == pytest.approx(2.0 / 3**0.5)
    assert summary.ci95_low == pytest.approx(4.0 - 1.96 * summary.sem)
    assert summary.controller_ms_per_step == pytest.approx(1.0)
    assert summary.env_ms_per_step == pytest.approx(2.0)


def test_paired_seeds_give_paired_results() -> None:
    env = marl_cover.parallel_env(hops=8, max_steps=20)
    local = evaluate(env, GreedyPolicy(8, fallback="random"), range(4))
    central = evaluate(env, CentralizedGreedyPolicy(8, fallback="random"), range(4))
    assert [r.reward for r in local.results] == [r.reward for r in central.results]
    again = evaluate(env, GreedyPolicy(8, fallback="random"), range(4))
    assert [r.reward for r in again.results] == [r.reward for r in local.results]
    assert all(0 < r.coverage <= 1 for r in local.results)


def evaluate_cli(*args: str) -> subprocess.CompletedProcess:
    return run_cli("evaluate", *args)


def test_cli_writes_json_and_csv(tmp_path) -> None:
    out = tmp_path / "greedy.json"
    result = evaluate_cli(
        "policy=greedy", "env.hops=5", "episodes=3", "seed=7", "env.max_steps=10", f"out={out}"
    )
    assert result.returncode == 0, result.stderr
    record = json.loads(out.read_text())
    assert record["summary"]["episodes"] == 3
    assert [r["seed"] for r in record["summary"]["results"]] == [7, 8, 9]
    assert out.with_suffix(".csv").read_text().splitlines()[0].startswith("seed,reward")


def test_cli_evaluates_a_receding_expert_blind_to_the_clock(tmp_path) -> None:
    pytest.importorskip("pyvrp")
    from marl_cover.agents.experts import RoutingExpert

    out = tmp_path / "blind.json"
    args = (
        "policy=expert_rh",
        "env.hops=4",
        "episodes=2",
        "seed=3",
        "env.max_steps=8",
        "env.num_robots=2",
    )
    result = evaluate_cli(*args, "expert.clock=false", "expert.iterations=20", f"out={out}")
    assert result.returncode == 0, result.stderr
    rewards = [r["reward"] for r in json.loads(out.read_text())["summary"]["results"]]
    env = marl_cover.parallel_env(max_steps=8, num_robots=2, hops=4)
    expert = RoutingExpert(mode="receding", horizon=4, clock=False, max_iterations=20)
    assert rewards == [r.reward for r in evaluate(env, expert, [3, 4]).results]
    result = evaluate_cli("policy=expert", "expert.clock=false")
    assert result.returncode != 0 and "policy=expert_rh and expert_local only" in result.stderr
    near = tmp_path / "near.json"
    result = evaluate_cli(*args, "expert.iterations=20", "expert.fallback_reach=2", f"out={near}")
    assert result.returncode == 0, result.stderr
    rewards = [r["reward"] for r in json.loads(near.read_text())["summary"]["results"]]
    expert = RoutingExpert(mode="receding", horizon=4, max_iterations=20, fallback_reach=2)
    assert rewards == [r.reward for r in evaluate(env, expert, [3, 4]).results]
    result = evaluate_cli("policy=gnn", "expert.fallback_reach=3")
    assert result.returncode != 0 and "policy=expert and expert_rh only" in result.stderr


def test_cli_evaluates_the_local_expert(tmp_path) -> None:
    pytest.importorskip("pyvrp")
    from marl_cover.agents.experts import LocalRoutingExpert

    out = tmp_path / "local.json"
    args = (
        "policy=expert_local",
        "env.hops=3",
        "episodes=2",
        "seed=3",
        "env.max_steps=8",
        "env.num_robots=3",
    )
    result = evaluate_cli(*args, "expert.clock=false", "expert.iterations=20", f"out={out}")
    assert result.returncode == 0, result.stderr
    record = json.loads(out.read_text())
    rewards = [r["reward"] for r in record["summary"]["results"]]
    env = marl_cover.parallel_env(max_steps=8, num_robots=3, hops=3)
    expert = LocalRoutingExpert(3, clock=False, max_iterations=20, fallback="random")
    assert rewards == [r.reward for r in evaluate(env, expert, [3, 4]).results]
    assert record["summary"]["policy_counts"]["solves"] == 2 * 8 * 3  # a solve per robot-step
    result = evaluate_cli("policy=expert_local", "expert.information=known")
    assert result.returncode != 0 and "does not apply to policy=expert_local" in result.stderr


def test_cli_rejects_unknown_keys() -> None:
    result = evaluate_cli("polcy=greedy")
    assert result.returncode != 0 and "polcy" in result.stderr
    result = evaluate_cli("expert.budget=3")
    assert result.returncode != 0 and "expert.budget" in result.stderr


@pytest.mark.parametrize(
    ("argument", "message"),
    [
        ("episodes=abc", "Value 'abc' of type 'str' could not be converted to Integer"),
        ("expert.time_limit=soon", "(full_key: expert.time_limit)"),
        ("env.num_robots=x", "(full_key: env.num_robots)"),
        ("env.window_fraction=3", "window_fraction must be in (0, 1], got 3"),
        ("gnn.temperature=0.5", "needs gnn.deterministic=false"),
        ("episodes=0", "episodes must be >= 1 and seed >= 0"),
        ("seed=-3", "episodes must be >= 1 and seed >= 0"),
        ("policy=greedy model=gnn", "model= applies to the gnn policies, not policy=greedy"),
        ("policy=gnn --seed -1", "episodes must be >= 1 and seed >= 0"),
        ("env.map=missing_grid.npy", "missing_grid.npy: occupancy grid not found"),
        ("model=README.md policy=gnn", "README.md: not a readable model file (UnpicklingError"),
        ("model=missing.pt policy=gnn", "no model file at missing.pt"),
        ("policy=gnn_rollout gnn.deterministic=false", "do not apply to policy=gnn_rollout"),
        ("policy=gnn gnn.spread=0.5 gnn.centralized=true", "on the robots' ego-graphs"),
        ("policy=greedy gnn.spread=0.5", "a margin >= 0 for policy=gnn"),
        ("policy=gnn gnn.spread=-1", "gnn.spread=-1.0: a margin >= 0"),
        ("policy=gnn gnn.margin=0.5", "apply to policy=gnn_local_rollout only"),
        ("policy=gnn_local_rollout gnn.horizon=0", "needs gnn.margin >= 0, gnn.horizon >= 1"),
        ("policy=gnn_local_rollout gnn.margin=-1", "got gnn.margin=-1.0 gnn.horizon=None"),
        ("policy=gnn_local_rollout gnn.greedy_after=-2", "gnn.greedy_after=-2"),
        ("policy=gnn gnn.greedy_after=1", "gnn.greedy_after applies to policy=gnn_rollout or"),
        ("policy=gnn_rollout gnn.greedy_after=0", "needs gnn.greedy_after >= 1 (or null), got 0"),
        ("policy=gnn_local_rollout gnn.centralized=true", "do not apply to policy=gnn_local"),
    ],
)
def test_cli_names_bad_values(argument: str, message: str) -> None:
    result = evaluate_cli(*argument.split())
    assert result.returncode != 0 and message in result.stderr
    assert "Traceback" not in result.stderr


def test_reproduce_paper_resumes_and_prints_the_table(tmp_path, paper_map_available) -> None:
    command = ["methods=[greedy]", "hops=[3]", "episodes=2", f"out={tmp_path}"]
    first = run_cli("reproduce-paper", *command)
    assert first.returncode == 0, first.stderr
    assert "done greedy K=3" in first.stdout
    record = json.loads((tmp_path / "greedy_K3.json").read_text())
    assert set(record) >= {"T50", "T49"}
    second = run_cli("reproduce-paper", *command)
    assert "done greedy" not in second.stdout  # resumed: nothing left to run
    assert "57.4 +- 1.66" in second.stdout  # the paper's greedy at K = 3, beside ours
    assert (tmp_path / "coverage.png").exists()


def test_cli_evaluates_a_gnn_checkpoint_both_ways(tmp_path) -> None:
    torch = pytest.importorskip("torch")
    from marl_cover.agents.models import AggregationGNN, GNNConfig
    from marl_cover.agents.models.checkpoints import save_model
    from marl_cover.agents.models.policy import GNNPolicy

    torch.manual_seed(0)
    model = AggregationGNN(GNNConfig(kind="nonlinear", hops=4))
    save_model(tmp_path / "m.pt", model, {"note": "random weights"})
    rewards = []
    for centralized in ("false", "true"):
        out = tmp_path / f"gnn_{centralized}.json"
        result = evaluate_cli(
            "policy=gnn",
            f"model={tmp_path / 'm.pt'}",
            f"gnn.centralized={centralized}",
            "episodes=3",
            "env.max_steps=10",
            f"out={out}",
        )
        assert result.returncode == 0, result.stderr
        record = json.loads(out.read_text())
        assert record["config"]["env"]["hops"] == 4  # the model's receptive field
        assert record["gnn"]["note"] == "random weights"
        rewards.append([r["reward"] for r in record["summary"]["results"]])
    env = marl_cover.parallel_env(hops=4, max_steps=10)
    for centralized, got in zip((False, True), rewards, strict=True):
        expected = evaluate(env, GNNPolicy(model, centralized=centralized), range(3))
        assert got == [r.reward for r in expected.results]
    result = evaluate_cli("policy=gnn", f"model={tmp_path / 'missing.pt'}", "episodes=1")
    assert result.returncode != 0 and "missing.pt" in result.stderr


def test_sampling_temperature_sharpens_toward_the_argmax() -> None:
    torch = pytest.importorskip("torch")
    from marl_cover.agents.models import AggregationGNN, GNNConfig
    from marl_cover.agents.models.policy import GNNPolicy

    torch.manual_seed(0)
    model = AggregationGNN(GNNConfig(kind="nonlinear", hops=3)).double()
    env = marl_cover.parallel_env(num_robots=4, hops=3, max_steps=10)
    observations, _ = env.reset(seed=0)
    argmax = GNNPolicy(model)
    logits = argmax.logits(observations)  # (4, 5), -inf where masked
    cold = GNNPolicy(model, deterministic=False, temperature=1e-9)
    assert cold.act(observations) == argmax.act(observations)
    # Very hot: every allowed move about equally often, never a masked one.
    hot = GNNPolicy(model, deterministic=False, temperature=1e9, seed=1)
    counts = np.zeros((4, 5))
    for _ in range(2000):
        counts[np.arange(4), list(hot.act(observations).values())] += 1
    allowed = torch.isfinite(logits).numpy()
    assert (counts[~allowed] == 0).all()
    expected = 2000 / allowed.sum(axis=1, keepdims=True)
    assert np.abs(counts - expected)[allowed].max() < 0.2 * expected.min()
    with pytest.raises(ValueError, match="temperature must be > 0, got 0"):
        GNNPolicy(model, deterministic=False, temperature=0)


def write_rewards(path: Path, rewards: dict[int, float]) -> Path:
    lines = ["seed,reward,coverage"] + [f"{s},{r},0.5" for s, r in rewards.items()]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_paired_comparison_of_two_runs(tmp_path: Path) -> None:
    from marl_cover.agents.evaluation.comparison import compare, read_rewards

    base = read_rewards(write_rewards(tmp_path / "a.csv", {0: 10.0, 1: 20.0, 2: 30.0}))
    # same seeds in another order: differences +2, -1, +5
    other = read_rewards(write_rewards(tmp_path / "b.csv", {2: 35.0, 0: 12.0, 1: 19.0}))
    row = compare(base, other, "a", "b")
    assert (row.episodes, row.base_mean, row.other_mean) == (3, 20.0, 22.0)
    assert row.difference == pytest.approx(2.0)
    assert row.difference_sem == pytest.approx(3.0 / 3**0.5)  # std of (2, -1, 5) is 3
    assert row.base_sem == pytest.approx(10.0 / 3**0.5)
    assert row.ratio == pytest.approx(1.1) and (row.wins, row.losses) == (2, 1)
    # per-seed ratios 1.2, 0.95, 35 / 30
    assert row.seed_ratio == pytest.approx((1.2 + 0.95 + 35 / 30) / 3)


def write_mission(path: Path, seeds: list[int], totals: dict[str, list[float]]) -> Path:
    """A table shaped like run_mission.py's mission.json."""
    methods = {
        name: {"totals": values, "mean": sum(values) / len(values)}
        for name, values in totals.items()
    }
    path.write_text(json.dumps({"config": {}, "seeds": seeds, "methods": methods, "over_time": {}}))
    return path


def test_mission_tables_are_paired_by_method(tmp_path: Path) -> None:
    from marl_cover.agents.evaluation.comparison import compare, read_run

    table = write_mission(
        tmp_path / "mission.json", [3, 4], {"greedy": [100.0, 200.0], "gnn": [130.0, 220.0]}
    )
    greedy, gnn = read_run(f"{table}:greedy"), read_run(table)  # gnn by default
    assert greedy == {3: 100.0, 4: 200.0} and gnn == {3: 130.0, 4: 220.0}
    assert read_run(f"{table}:gnn") == gnn
    row = compare(greedy, gnn, "greedy", "gnn")
    assert row.seed_ratio == pytest.approx(1.2) and row.seed_ratio_sem == pytest.approx(0.1)
    assert row.ratio == pytest.approx(350 / 300)
    with pytest.raises(
        ValueError,
        match=r"mission.json: no method 'expert' with totals \(has \['gnn', 'greedy'\]\)",
    ):
        read_run(f"{table}:expert")
    not_a_table = tmp_path / "eval.json"
    not_a_table.write_text(json.dumps({"summary": {}}))
    with pytest.raises(ValueError, match="eval.json: not a mission table"):
        read_run(not_a_table)


def test_comparison_refuses_unpaired_or_broken_files(tmp_path: Path) -> None:
    from marl_cover.agents.evaluation.comparison import compare, read_rewards

    with pytest.raises(ValueError, match=r"a and b are not paired: seeds only in a \[2\] \(1\)"):
        compare({0: 1.0, 1: 1.0, 2: 1.0}, {0: 1.0, 1: 2.0}, "a", "b")
    twice = tmp_path / "twice.csv"
    twice.write_text("seed,reward\n0,1\n0,2\n")
    with pytest.raises(ValueError, match="twice.csv: line 3: seed 0 appears twice"):
        read_rewards(twice)
    no_reward = tmp_path / "no_reward.csv"
    no_reward.write_text("seed,score\n0,1\n")
    with pytest.raises(ValueError, match=r"no_reward.csv: no column \['reward'\]"):
        read_rewards(no_reward)
    binary = tmp_path / "model.pt"
    binary.write_bytes(b"PK\x03\x04\x80\x81\xff")
    with pytest.raises(ValueError, match=r"model.pt: not a text file"):
        read_rewards(binary)
    text = tmp_path / "text.csv"
    text.write_text("seed,reward\n0,lots\n")
    with pytest.raises(ValueError, match="text.csv: line 2: .* is not a number"):
        read_rewards(text)


def test_compare_script_prints_and_writes_the_table(tmp_path: Path) -> None:
    base = write_rewards(tmp_path / "greedy.csv", {0: 10.0, 1: 20.0})
    other = write_rewards(tmp_path / "gnn.csv", {0: 13.0, 1: 21.0})
    out = tmp_path / "cmp.json"
    done = run_cli("compare", f"runs=[{base},{other}]", f"out={out}")
    assert done.returncode == 0, done.stderr
    assert "+2.00 +- 1.00" in done.stdout and "1.133" in done.stdout
    assert "1.175 +- 0.125" in done.stdout  # per-seed ratios 1.3 and 1.05
    assert json.loads(out.read_text())[0]["difference"] == 2.0
    bad = run_cli("compare", f"runs=[{base},{tmp_path / 'missing.csv'}]")
    assert bad.returncode == 1 and "missing.csv" in bad.stderr


def test_generalize_names_a_bad_model_file() -> None:
    for path, message in (
        ("no.pt", "no model file at no.pt"),
        ("README.md", "README.md: not a readable model file"),
    ):
        result = run_cli("generalize", f"model={path}", "robots=[10]")
        assert result.returncode != 0 and message in result.stderr
        assert "Traceback" not in result.stderr


def test_generalize_on_cities_sized_by_the_team(tmp_path) -> None:
    """map=city: cities of waypoints_per_robot waypoints a robot, paired seeds, the table of
    rewards per robot and ratios, the CSV and the plot; a second run reads the results back."""
    out = tmp_path / "gen"
    args = ["map=city", "robots=[3,6]", "episodes=2", "waypoints_per_robot=40", f"out={out}"]
    args.append("methods=[greedy,gnn,assign,reach,route]")
    done = run_cli("generalize", *args)
    assert done.returncode == 0, done.stderr
    rows = (out / "generalize.csv").read_text().splitlines()
    header = rows[0].split(",")
    assert header[:3] == ["robots", "waypoints", "episodes"] and len(rows) == 3
    first = dict(zip(header, rows[1].split(","), strict=True))
    assert (first["robots"], first["waypoints"], first["episodes"]) == ("3", "120", "2")
    gnn = json.loads((out / "gnn_R3.json").read_text())
    greedy = json.loads((out / "greedy_R3.json").read_text())
    assert float(first["gnn_per_robot"]) == pytest.approx(gnn["mean"] / 3)
    paired = np.array(gnn["rewards"]) / np.maximum(np.array(greedy["rewards"]), 1)
    assert float(first["paired_ratio_mean"]) == pytest.approx(paired.mean())
    assert (out / "generalize.png").exists() and "| 6 | 240 |" in done.stdout
    assign = json.loads((out / "assign_R3.json").read_text())["rewards"]
    reach = json.loads((out / "reach_R3.json").read_text())["rewards"]  # bounds on any policy
    route = json.loads((out / "route_R3.json").read_text())["rewards"]
    for *bounds, a, b, c in zip(
        reach, route, greedy["rewards"], gnn["rewards"], assign, strict=True
    ):
        assert bounds[0] >= bounds[1] >= max(a, b, c)
    assert float(first["reach_bound"]) == pytest.approx(np.mean(reach))
    assert float(first["route_bound"]) == pytest.approx(np.mean(route))
    assert float(first["gnn_of_bound"]) == pytest.approx(gnn["mean"] / np.mean(route))
    assert float(first["assign_mean"]) == pytest.approx(np.mean(assign))
    again = run_cli("generalize", *args)
    assert again.returncode == 0 and "done" not in again.stdout  # read back, nothing replayed
