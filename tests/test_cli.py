"""The ``marl-cover`` command line: every subcommand's help, the three layers of settings
(preset, ``key=value``, ``--flag``), and the errors that name what is wrong."""

from __future__ import annotations

import re
import subprocess
import sys
from dataclasses import dataclass, field

import pytest
from helpers import ROOT, run_cli

from marl_cover.agents.cli import options
from marl_cover.agents.cli.main import COMMANDS, main
from marl_cover.config import EnvSettings


def test_the_top_level_help_lists_every_command(capsys: pytest.CaptureFixture) -> None:
    main(["--help"])
    text = capsys.readouterr().out
    for name in COMMANDS:
        assert re.search(rf"^  {re.escape(name)} ", text, re.M), name
    main(["--version"])
    assert capsys.readouterr().out.startswith("marl-cover 1.")
    with pytest.raises(SystemExit, match="unknown command 'train'; commands: demo, evaluate"):
        main(["train"])


@pytest.mark.parametrize("name", list(COMMANDS))
def test_every_command_lists_its_options_with_types_and_defaults(name: str) -> None:
    if name in ("train-bc", "train-mappo", "sweep", "bench-gnn", "average"):
        pytest.importorskip("torch")
    done = run_cli(name, "--help")
    assert done.returncode == 0, done.stderr
    text = done.stdout
    assert f"usage: marl-cover {name}" in text
    assert "-h, --help" in text and "key=value" in text
    listed = [name for name in re.findall(r"^\W*(--[a-z_.]+)", text, re.M) if name != "--help"]
    assert listed and text.count("(default:") >= len(listed)
    types = re.findall(r"^\W*--[a-z_.]+ (\S+)", text, re.M)
    assert all(re.fullmatch(r"[A-Z{\[][\w{}|.,\[\] ]*", kind) for kind in types), types


def test_the_installed_console_script_runs() -> None:
    """``marl-cover`` as the entry point pip installs, in its own interpreter."""
    script = ROOT / ".venv" / "bin" / "marl-cover"
    command = (
        [str(script)] if script.exists() else [sys.executable, "-m", "marl_cover.agents.cli.main"]
    )
    done = subprocess.run(
        [*command, "evaluate", "--help"], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert "--env.num_robots INT" in done.stdout and "(default: 4)" in done.stdout


@dataclass
class Inner:
    """A section."""

    hops: int = 3  # the inner count
    rate: float | None = None  # a rate


@dataclass
class Outer:
    """A config with a section and an environment."""

    name: str = "run"  # a name
    seeds: list[int] = field(default_factory=lambda: [0, 1])  # some seeds
    inner: Inner = field(default_factory=Inner)
    env: EnvSettings = field(default_factory=EnvSettings)


def test_settings_come_in_three_layers(tmp_path) -> None:
    preset = tmp_path / "preset.yaml"
    preset.write_text("name: preset\ninner: {hops: 5}\nenv: {map: paper, num_robots: 7}\n")
    args = ["--config", str(preset), "inner.rate=0.5", "seeds=[4,5,6]", "--name", "flag"]
    config = options.parse(Outer, args, prog="test", description="x")
    assert config == Outer(
        name="flag",  # the flag over the preset
        seeds=[4, 5, 6],
        inner=Inner(hops=5, rate=0.5),
        env=EnvSettings(map="paper", num_robots=7),
    )
    assert (
        options.parse(Outer, ["env.hops=7", "--env.hops", "9"], prog="t", description="").env.hops
        == 9
    )


def test_print_config_round_trips(tmp_path, capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as done:
        options.parse(Outer, ["--print-config", "inner.hops=8"], prog="t", description="")
    assert done.value.code == 0
    printed = tmp_path / "printed.yaml"
    printed.write_text(capsys.readouterr().out)
    assert options.load(Outer, printed) == Outer(inner=Inner(hops=8))


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["inner.depth=3"], "Key 'depth' not in 'Inner' (full_key: inner.depth)"),
        (["seeds=[a]"], "could not be converted to Integer"),
        (["env.num_robots=0"], "num_robots must be >= 1, got 0"),
        (["--config", "nothing_here"], "no config file or preset 'nothing_here'; presets: ["),
        (["--config"], "--config needs a preset name or a YAML file"),
        (["env.task=flying"], "task must be one of ('coverage', 'exploration'), got 'flying'"),
    ],
)
def test_bad_settings_end_with_one_line_that_names_them(args: list[str], message: str) -> None:
    with pytest.raises(SystemExit) as done:
        options.parse(Outer, args, prog="marl-cover test", description="")
    assert str(done.value).startswith("marl-cover test: ")
    assert message in str(done.value) and "\n" not in str(done.value)


def test_presets_are_found_by_name_from_any_folder(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    names = options.preset_names()
    assert {"bc_coverage", "mappo_coverage", "mappo_finetune", "mission"} <= set(names)
    assert options.preset_path("mappo_finetune").name == "mappo_finetune.yaml"
    assert options.preset_path("configs/mappo_finetune.yaml").is_file()  # an old-style path
    with pytest.raises(options.ConfigError, match="no config file or preset"):
        options.preset_path("mappo_fine")


def test_a_command_reads_its_default_preset(tmp_path) -> None:
    pytest.importorskip("torch")
    done = run_cli("train-mappo", "--print-config", f"out={tmp_path / 'x'}")
    assert done.returncode == 0, done.stderr
    assert "out: " in done.stdout and "n_iters: 250" in done.stdout  # mappo_coverage
    done = run_cli("train-mappo", "--print-config", "--config", "mappo_finetune_8000")
    assert "frames_per_batch: 8000" in done.stdout
