"""The README is the front door: its first lines give the two commands, it stays short, and
every command of its results table is a valid ``marl-cover`` command line. (Its code blocks run
in ``test_docs.py``.)"""

from __future__ import annotations

import re
import shlex

import pytest
from helpers import ROOT, run_cli

README = (ROOT / "README.md").read_text()


def test_the_first_lines_give_the_two_commands() -> None:
    head = "\n".join(README.splitlines()[:8])
    assert "`make demo`" in head and "`make test`" in head
    assert len(README.splitlines()) <= 220


def results_rows() -> list[list[str]]:
    section = README.split("## Results", 1)[1].split("\n## ", 1)[0]
    rows = [
        [cell.strip() for cell in line.strip().strip("|").split("|")]
        for line in section.splitlines()
        if line.startswith("| ")
    ]
    assert [cell.strip() for cell in rows[0]] == ["task", "method", "ours", "paper", "command"]
    return rows[1:]


def test_the_results_table_has_a_command_on_every_row() -> None:
    rows = results_rows()
    assert len(rows) >= 12
    for row in rows:
        assert re.search(r"`marl-cover [a-z-]+", row[4]), row


@pytest.mark.parametrize("row", range(16))
def test_every_command_of_the_results_table_parses(row: int) -> None:
    pytest.importorskip("torch")
    rows = results_rows()
    if row >= len(rows):
        pytest.skip("fewer rows")
    for command in re.findall(r"`(marl-cover [^`]+)`", rows[row][4]):
        name, *args = shlex.split(command)[1:]
        done = run_cli(name, *args, "--print-config")
        assert done.returncode == 0, f"{command}: {done.stderr[-1000:]}"
