"""`make demo`'s script: the three policies' rows and the animation."""

from __future__ import annotations

import pytest
from helpers import run_script


@pytest.mark.parametrize(
    ("task", "experts", "gif"),
    [
        ("coverage", ["expert"], "gnn_city.gif"),
        ("exploration", ["expert", "expert"], "gnn_city_explore.gif"),  # omniscient, fair
    ],
)
def test_demo_prints_the_comparison_and_writes_a_gif(tmp_path, task, experts, gif) -> None:
    pytest.importorskip("torch")
    pytest.importorskip("pyvrp")
    pytest.importorskip("matplotlib")
    result = run_script(
        "demo.py",
        *[
            "--task",
            task,
            "--episodes",
            "1",
            "--city_size",
            "120",
            "--expert_iterations",
            "50",
            "--out",
            str(tmp_path),
        ],
    )
    assert result.returncode == 0, result.stderr
    rows = [line for line in result.stdout.splitlines() if "+-" in line]
    assert [row.split(",")[0].split(" (")[0] for row in rows] == [
        "GNN nonlinear",
        "greedy",
        *experts,
    ]
    assert (tmp_path / gif).read_bytes()[:6] == b"GIF89a"
