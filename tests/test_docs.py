"""The documentation: the site builds with ``mkdocs build --strict``, every code block of the
README and the guides runs as written, and the product speaks of itself (no history of how it
was made)."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import ROOT, run_cli

PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
FENCE = re.compile(r"^```(\w+)\n(.*?)^```", re.M | re.S)


def blocks(page: Path) -> list[tuple[str, str]]:
    """The fenced code blocks of a page: ``(language, code)``."""
    return FENCE.findall(page.read_text())


def commands(code: str) -> list[str]:
    """The command lines of a shell block (``\\`` continues a line; comments skipped)."""
    joined = code.replace("\\\n", " ")
    return [
        line.strip() for line in joined.splitlines() if line.strip() and not line.startswith("#")
    ]


def test_every_block_is_python_or_bash() -> None:
    found = [(page.name, language) for page in PAGES for language, _ in blocks(page)]
    assert found and {language for _, language in found} <= {"python", "bash"}, found


@pytest.mark.usefixtures("paper_map_available")
@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_the_code_blocks_run(page: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A page's Python blocks run in order in one namespace, and its shell blocks line by line
    (``marl-cover`` in this process, anything else in a shell), all in an empty folder."""
    pytest.importorskip("torch")
    pytest.importorskip("pyvrp")
    pytest.importorskip("matplotlib")
    monkeypatch.chdir(tmp_path)
    # the shell finds the environment's own commands (ray, mkdocs) as in an activated venv
    monkeypatch.setenv("PATH", f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    if "ray start" in page.read_text():
        pytest.importorskip("ray")
    try:
        run_page(page, tmp_path)
        if "ray start" in page.read_text():  # the commands ran here, and left no connection
            import ray

            assert not ray.is_initialized()
    finally:
        if "ray start" in page.read_text():  # never leave a cluster behind
            subprocess.run(["ray", "stop", "--force"], capture_output=True, check=False)


def run_page(page: Path, tmp_path: Path) -> None:
    """Runs a page's blocks in order (see :func:`test_the_code_blocks_run`)."""
    namespace: dict = {"__name__": "__docs__"}
    for index, (language, code) in enumerate(blocks(page)):
        if language == "python":
            exec(compile(code, f"{page.name} block {index}", "exec"), namespace)  # noqa: S102
            continue
        for line in commands(code):
            words = shlex.split(line)
            if words[0] == "marl-cover":
                done = run_cli(*words[1:], cwd=tmp_path) if len(words) > 1 else run_cli("--help")
            else:
                done = subprocess.run(
                    line, shell=True, cwd=tmp_path, capture_output=True, text=True
                )
            assert done.returncode == 0, (
                f"{page.name}: {line}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
            )


def test_the_site_builds_strictly(tmp_path: Path) -> None:
    pytest.importorskip("mkdocs")
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert (tmp_path / "site" / "index.html").is_file()
    assert (tmp_path / "site" / "results" / "what-we-tried" / "index.html").is_file()


#: Words of a lab notebook, not of a product.
HISTORY = re.compile(
    r"(?<![\"'])\bsessions?\b(?![\"'])|\bsession[-_ ]\d|\bprob(?:e|es|ed|ing)\b|\bissues?\s*#?\d+|"
    r"\b20\d\d-\d\d-\d\d\b|\bgit worktree\b",
    re.I,
)


def product_files() -> list[Path]:
    roots = [
        "README.md",
        "CHANGELOG.md",
        "mkdocs.yml",
        "docs",
        "marl_cover",
        "agents",
        "configs",
        "scripts",
    ]
    files: list[Path] = []
    for name in roots:
        path = ROOT / name
        candidates = [path] if path.is_file() else path.rglob("*")
        files += [
            p for p in candidates if p.suffix in {".md", ".py", ".yaml", ".yml", ".json", ".csv"}
        ]
    return files


def test_the_product_speaks_of_itself() -> None:
    """No history of how the project was made in the README, docs, code, configs or model
    cards: the history lives in the git log."""
    found = []
    for path in product_files():
        for number, line in enumerate(path.read_text().splitlines(), start=1):
            if HISTORY.search(line):
                found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()[:120]}")
    assert not found, "\n".join(found)


def test_the_history_check_catches_what_it_should() -> None:
    for text in (
        "since session 20",
        "a session-53 probe",
        "issue 5's target",
        "issue #63",
        "2026-12-05",
    ):
        assert HISTORY.search(text), text
    for text in ('scope="session"', "the expert's problem"):
        assert not HISTORY.search(text), text
