"""agents.mission_diagnostics: decisions sorted by view and move, on a line of waypoints."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from helpers import run_script

from agents.configuration import load
from agents.greedy import GreedyPolicy
from agents.mission import MissionConfig, make_mission_policy, run_mission
from agents.mission_diagnostics import DecisionRecorder
from marl_cover.continuous import QuadrotorCoverageEnv

ROOT = Path(__file__).resolve().parent.parent

EAST, WEST = 1, 3


class East:
    """Always east."""

    def act(self, observations: dict) -> dict[str, int]:
        return dict.fromkeys(observations, EAST)


class Stay:
    """Always stay."""

    def act(self, observations: dict) -> dict[str, int]:
        return dict.fromkeys(observations, 0)


class PingPong:
    """East, west, east, ... (one toggle per decision of each robot)."""

    def __init__(self) -> None:
        self.calls = 0

    def act(self, observations: dict) -> dict[str, int]:
        self.calls += len(observations)
        return {a: EAST if self.calls % 2 else WEST for a in observations}


def fly(env: QuadrotorCoverageEnv, recorder: DecisionRecorder, interest: list[int]) -> None:
    """One mission from waypoint 2, every ready robot asked at every step (no caching)."""
    recorder.reset(0)
    observations, _ = env.reset(seed=0, options={"robot_nodes": [2], "interest_nodes": interest})
    while env.agents:
        ready = [a for a, r in zip(env.possible_agents, env.ready, strict=True) if r]
        chosen = recorder.act({a: observations[a] for a in ready})
        observations, *_ = env.step({a: chosen.get(a, 0) for a in env.possible_agents})


def line_env(path_graph) -> QuadrotorCoverageEnv:
    return QuadrotorCoverageEnv(graph=path_graph, num_robots=1, hops=2, dynamics={"max_time": 60.0})


def test_decisions_sorted_by_view_and_move(path_graph) -> None:
    """From 2 east with points of interest at 5 and 7 (hops = 2): at 2 both are 3 or more hops
    away (blind); at 3, 4, 5 and 6 one is in view; at 7 the last is visited and the mission ends.
    A robot that stays at 2 is blind at every decision."""
    env = line_env(path_graph)
    recorder = DecisionRecorder(East(), env)
    fly(env, recorder, interest=[5, 7])
    assert recorder.table() == {
        "in view": {"stay": 0, "back": 0, "forward": 4},
        "blind": {"stay": 0, "back": 0, "forward": 1},
    }
    recorder = DecisionRecorder(Stay(), env)
    fly(env, recorder, interest=[5, 7])
    table = recorder.table()
    assert sum(table["in view"].values()) == 0
    assert table["blind"]["stay"] > 0 and table["blind"]["forward"] == table["blind"]["back"] == 0


def test_ping_pong_goes_back_on_every_decision_but_the_first(path_graph) -> None:
    env = line_env(path_graph)
    recorder = DecisionRecorder(PingPong(), env)
    fly(env, recorder, interest=[7])  # 5 hops from 2, 4 from 3: never in view
    table = recorder.table()
    assert sum(table["in view"].values()) == 0
    assert table["blind"]["forward"] == 1 and table["blind"]["stay"] == 0
    assert table["blind"]["back"] >= 3


def test_random_blind_moves_replace_only_blind_decisions(path_graph) -> None:
    """With ``blind="random"`` the ping-pong robot no longer goes back every time, the moves
    are available ones (never stay), and the same seed gives the same decisions."""
    env = line_env(path_graph)
    tables = []
    for _ in range(2):
        recorder = DecisionRecorder(PingPong(), env, blind="random")
        assert not recorder.deterministic
        fly(env, recorder, interest=[7])
        tables.append(recorder.table())
    assert tables[0] == tables[1]
    assert tables[0]["blind"]["stay"] == 0
    assert tables[0]["blind"]["forward"] > 1


def test_blind_rules_are_checked(path_graph) -> None:
    env = line_env(path_graph)
    with pytest.raises(ValueError, match="unknown blind rule 'walk'"):
        DecisionRecorder(GreedyPolicy(2), env, blind="walk")
    with pytest.raises(ValueError, match="GreedyPolicy has no logits"):
        DecisionRecorder(GreedyPolicy(2), env, blind="sample")


def test_recorded_mission_is_the_policy_mission() -> None:
    """With ``blind="policy"`` the recorder changes nothing: the same mission as the policy."""
    config = MissionConfig(
        map="city", num_robots=3, hops=6, seeds=1, dynamics={"max_time": 40.0}, methods=["gnn"]
    )
    env = config.make_env()
    alone = run_mission(env, make_mission_policy("gnn", config), seed=2)
    recorder = DecisionRecorder(make_mission_policy("gnn", config), env)
    recorded = run_mission(env, recorder, seed=2)
    assert recorded.visited == alone.visited
    assert recorded.decisions == alone.decisions > 0
    # in arrival mode a step ends when a robot arrives: every ask has a ready robot
    assert sum(sum(row.values()) for row in recorder.table().values()) >= alone.decisions


def test_nearest_blind_moves_head_for_the_nearest_point_anywhere(path_graph) -> None:
    """With ``blind="nearest"`` a robot that would stay, blind to the point at 7 (hops = 2),
    walks east instead on every blind decision (2 -> 3 -> 4 -> 5) and stays from 5 on, where
    it sees the point; from 4 with the point at 0 it goes west."""
    env = line_env(path_graph)
    recorder = DecisionRecorder(Stay(), env, blind="nearest")
    assert not recorder.deterministic
    fly(env, recorder, interest=[7])
    table = recorder.table()
    assert table["blind"] == {"stay": 0, "back": 0, "forward": 3}
    assert table["in view"]["stay"] > 0 and table["in view"]["forward"] == 0
    assert int(env.snapped[0]) == 5 and not env.snapshot().visited[7]
    recorder.reset(0)
    observations, _ = env.reset(seed=0, options={"robot_nodes": [4], "interest_nodes": [0]})
    assert recorder.act({"robot_0": observations["robot_0"]}) == {"robot_0": WEST}


def test_diagnose_script_sorts_every_decision_of_the_missions(tmp_path: Path) -> None:
    """With the policy's own blind moves the script flies greedy's own missions (the totals of
    ``run_mission`` alone), and its table is a :class:`DecisionRecorder`'s over them."""
    out = tmp_path / "diag.json"
    args = ["methods=[greedy]", "seeds=2", "map=city", "num_robots=3", "hops=2"]
    args += ["dynamics.max_time=20"]
    done = run_script("diagnose_mission.py", "--out", str(out), *args)
    assert done.returncode == 0, done.stderr
    result = json.loads(out.read_text())["methods"]["greedy"]
    config = load(MissionConfig, ROOT / "configs/mission.yaml", args)
    env = config.make_env()
    alone = [run_mission(env, make_mission_policy("greedy", config), seed) for seed in (0, 1)]
    assert result["totals"] == [r.total for r in alone]  # the recorder changes nothing
    recorder = DecisionRecorder(make_mission_policy("greedy", config), env)
    for seed in (0, 1):
        run_mission(env, recorder, seed)
    assert result["decisions"] == recorder.table()
    assert sum(result["decisions"]["blind"].values()) > 0  # two hops leave robots blind
    refused = run_script("diagnose_mission.py", "--out", str(out), "methods=[expert]")
    assert refused.returncode != 0 and "no decentralized method" in refused.stderr
