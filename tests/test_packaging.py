"""The release: the wheel and the sdist build and pass ``twine check``; the wheel installs
(core only) into a fresh virtualenv, where the environment passes PettingZoo's checker and no
top-level ``agents`` package appears; and every module imports from the installed wheel,
outside the repository."""

from __future__ import annotations

import os
import subprocess
import sys
import tarfile
import textwrap
import zipfile
from pathlib import Path

import pytest
from helpers import ROOT

import marl_cover

pytest.importorskip("build")


def run(command: list[str], **kwargs) -> subprocess.CompletedProcess:  # noqa: ANN003
    done = subprocess.run(command, capture_output=True, text=True, timeout=900, **kwargs)
    assert done.returncode == 0, f"{command}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    return done


@pytest.fixture(scope="module")
def dist(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("dist")
    run([sys.executable, "-m", "build", "--no-isolation", "--outdir", str(out), str(ROOT)])
    (wheel,) = out.glob("marl_cover-*.whl")
    (sdist,) = out.glob("marl_cover-*.tar.gz")
    return {"wheel": wheel, "sdist": sdist}


def test_twine_checks_both(dist: dict[str, Path]) -> None:
    pytest.importorskip("twine")
    done = run([sys.executable, "-m", "twine", "check", "--strict", *map(str, dist.values())])
    assert done.stdout.count("PASSED") == 2


def test_the_wheel_holds_the_package_its_data_and_nothing_else(dist: dict[str, Path]) -> None:
    names = zipfile.ZipFile(dist["wheel"]).namelist()
    tops = {name.split("/")[0] for name in names}
    info = f"marl_cover-{marl_cover.__version__}.dist-info"
    assert tops == {"marl_cover", info}
    shipped = sorted(n for n in names if n.startswith("marl_cover/agents/models/shipped/"))
    assert [n for n in shipped if n.endswith(".pt")] == [
        f"marl_cover/agents/models/shipped/{name}.pt"
        for name in ("gnn", "gnn_exploration", "gnn_linear", "gnn_mappo", "gnn_mission")
    ]
    assert len([n for n in shipped if n.endswith(".json")]) == 5
    assert "marl_cover/configs/mappo_finetune.yaml" in names
    assert "marl_cover/agents/evaluation/paper_results.csv" in names
    assert "marl_cover/py.typed" in names
    entry_points = zipfile.ZipFile(dist["wheel"]).read(f"{info}/entry_points.txt")
    assert b"marl-cover = marl_cover.agents.cli.main:main" in entry_points
    metadata = zipfile.ZipFile(dist["wheel"]).read(f"{info}/METADATA")
    assert b"License-Expression: MIT" in metadata


def test_the_sdist_holds_what_its_tests_need(dist: dict[str, Path]) -> None:
    with tarfile.open(dist["sdist"]) as sdist:
        names = {n.split("/", 1)[1] for n in sdist.getnames() if "/" in n}
    for needed in (
        "tests/conftest.py",
        "tests/helpers.py",
        "tests/typecheck.py",
        "configs/mission.yaml",
        "constraints.txt",
        "Makefile",
        "mkdocs.yml",
        "docs/index.md",
        "LICENSE",
        "CHANGELOG.md",
    ):
        assert needed in names, needed


CORE_CHECK = textwrap.dedent(
    """
    import importlib.util
    import json
    import pkgutil
    import sys

    import marl_cover
    import marl_cover.agents
    from pettingzoo.test import parallel_api_test

    assert "site-packages" in marl_cover.__file__, marl_cover.__file__
    assert importlib.util.find_spec("agents") is None  # nothing under a generic name
    assert importlib.util.find_spec("torch") is None  # the core install
    parallel_api_test(marl_cover.parallel_env(city_size=120, hops=4), num_cycles=40)
    from marl_cover.agents.evaluation.paper import paper_numbers
    from marl_cover.agents.models.shipped import model_card

    assert paper_numbers("coverage")[("gnn_nonlinear_bc", 19)][0] == 77.5
    assert model_card("gnn")["test"]["mean"] > 80
    print("core ok")
    """
)


def test_the_wheel_installs_core_only_into_a_fresh_virtualenv(
    dist: dict[str, Path], tmp_path: Path
) -> None:
    venv = tmp_path / "venv"
    run([sys.executable, "-m", "venv", str(venv)])
    python, pip = venv / "bin" / "python", venv / "bin" / "pip"
    install = [str(pip), "install", "--quiet", "--disable-pip-version-check"]
    run([*install, "-c", str(ROOT / "constraints.txt"), str(dist["wheel"])])
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    done = run([str(python), "-c", CORE_CHECK], cwd=outside, env=env)
    assert done.stdout.strip().endswith("core ok")
    cli = str(venv / "bin" / "marl-cover")
    assert "train-mappo" in run([cli, "--help"], cwd=outside, env=env).stdout
    out = outside / "greedy.json"
    args = ["policy=greedy", "episodes=2", "env.city_size=90", f"out={out}"]
    assert (
        "greedy on city, 2 episodes" in run([cli, "evaluate", *args], cwd=outside, env=env).stdout
    )
    refused = subprocess.run(
        [cli, "train-mappo", "--help"], cwd=outside, env=env, capture_output=True, text=True
    )
    assert refused.returncode != 0
    assert "pip install 'marl-cover[train]'" in refused.stderr


IMPORT_ALL = textwrap.dedent(
    """
    import importlib
    import pkgutil
    import sys

    import marl_cover

    target = sys.argv[1]
    names = ["marl_cover"]
    for info in pkgutil.walk_packages(marl_cover.__path__, "marl_cover."):
        names.append(info.name)
    for name in names:
        module = importlib.import_module(name)
        assert module.__file__.startswith(target), (name, module.__file__)
    assert "marl_cover.agents.training.mappo" in names and "marl_cover.configs" in names
    print(len(names), "modules")
    """
)


def test_every_module_imports_from_the_installed_wheel(
    dist: dict[str, Path], tmp_path: Path
) -> None:
    """The wheel's files alone (no checkout on the path), with the extras this machine has:
    every module imports, and the commands find presets and shipped models by name."""
    pytest.importorskip("torch")
    pytest.importorskip("pyvrp")
    target = tmp_path / "site"
    run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--quiet",
            "--no-deps",
            "--target",
            str(target),
            str(dist["wheel"]),
        ]
    )
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    env = {**os.environ, "PYTHONPATH": str(target)}
    done = run([sys.executable, "-c", IMPORT_ALL, str(target)], cwd=outside, env=env)
    assert int(done.stdout.split()[0]) > 60
    main = [sys.executable, "-m", "marl_cover.agents.cli.main"]
    printed = run(
        [*main, "train-mappo", "--print-config", "--config", "mappo_finetune"], cwd=outside, env=env
    )
    assert "init: outputs/bc/nonlinear_k19/best.pt" in printed.stdout
    out = outside / "gnn.json"
    args = ["policy=gnn", "model=gnn_linear", "episodes=1", "env.city_size=90", f"out={out}"]
    assert "gnn on city, 1 episodes" in run([*main, "evaluate", *args], cwd=outside, env=env).stdout
