"""Helpers shared by the tests."""

from __future__ import annotations

import contextlib
import io
import os
import runpy
import subprocess
import sys
import traceback
from collections.abc import Callable
from pathlib import Path

import numpy as np

from marl_cover.graph import SpatialGraph

ROOT = Path(__file__).resolve().parent.parent
#: ``marl-cover collect`` settings of a five-episode, three-shard dataset (seconds to collect).
TINY_DATASET = (
    "episodes=5",
    "shard_size=2",
    "env.map=city",
    "env.city_size=120",
    "env.max_steps=15",
    "env.hops=6",
    "expert.iterations=100",
)


def random_grid_graph(
    rng: np.random.Generator, rows: int, cols: int, density: float
) -> SpatialGraph:
    """The largest component of a random set of grid cells."""
    from marl_cover.maps import graph_from_occupancy

    occupied = rng.random((rows, cols)) > density
    occupied[rng.integers(rows), rng.integers(cols)] = False
    return graph_from_occupancy(occupied, cell_size=5.0)


def run_cli(command: str, *args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    """``marl-cover <command> <args>`` from the repository root, run in this process.

    The command line's entry runs (argument parsing and exit codes included) without a new
    interpreter: no second import of torch and TorchRL, about 5 s a call on the CI machines.
    Use a real subprocess where the command starts worker processes.

    Returns:
        What ``subprocess.run(..., capture_output=True, text=True)`` returns: the exit code
        (``SystemExit``'s, or 1 and the traceback in ``stderr`` for an uncaught exception),
        ``stdout`` and ``stderr``.
    """
    from marl_cover.agents.cli.main import main

    return _in_process(["marl-cover", command, *args], lambda: main([command, *args]), cwd)


def run_script(script: str, *args: str) -> subprocess.CompletedProcess:
    """``python scripts/<script> <args>`` from the repository root, run in this process (as
    :func:`run_cli`)."""
    path = ROOT / "scripts" / script
    return _in_process(
        [sys.executable, str(path), *args], lambda: runpy.run_path(str(path), run_name="__main__")
    )


def _in_process(
    argv: list[str], call: Callable[[], object], cwd: Path = ROOT
) -> subprocess.CompletedProcess:
    stdout, stderr = io.StringIO(), io.StringIO()
    saved_argv, saved_cwd, saved_path = sys.argv, os.getcwd(), list(sys.path)
    code = 0
    try:
        os.chdir(cwd)
        sys.argv = [argv[1] if argv[0] == sys.executable else argv[0], *argv[2:]]
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            try:
                call()
            except SystemExit as exit_:
                if isinstance(exit_.code, int):
                    code = exit_.code
                elif exit_.code is not None:  # sys.exit("message"): printed, status 1
                    print(exit_.code, file=sys.stderr)
                    code = 1
            except Exception:  # noqa: BLE001 (the process would print it and exit 1)
                traceback.print_exc()
                code = 1
    finally:
        sys.argv, sys.path[:] = saved_argv, saved_path
        os.chdir(saved_cwd)
    return subprocess.CompletedProcess(argv, code, stdout.getvalue(), stderr.getvalue())
