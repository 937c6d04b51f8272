"""mypy on the installed layout: ``marl_cover`` with ``agents/`` as ``marl_cover.agents``.

The repository keeps ``agents/`` beside ``marl_cover/`` and installs it as
``marl_cover.agents`` (setuptools ``package-dir``); mypy reads packages from folders, so it
checks a tree of links laid out as the installed package, and ``scripts/``.

    python tests/typecheck.py        # prints mypy's report; exits with its status
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def run_mypy() -> tuple[str, int]:
    """mypy's report on the linked tree and its exit status."""
    from mypy import api

    with tempfile.TemporaryDirectory(prefix="marl_cover_typecheck_") as folder:
        tree = Path(folder)
        package = tree / "marl_cover"
        package.mkdir()
        for entry in (ROOT / "marl_cover").iterdir():
            if entry.name != "__pycache__":
                os.symlink(entry, package / entry.name)
        os.symlink(ROOT / "agents", package / "agents")
        os.symlink(ROOT / "configs", package / "configs")
        os.symlink(ROOT / "scripts", tree / "scripts")
        cache = ROOT / ".mypy_cache"
        arguments = ["--config-file", str(ROOT / "pyproject.toml"), "--cache-dir", str(cache)]
        saved = Path.cwd()
        os.chdir(tree)
        try:
            stdout, stderr, status = api.run([*arguments, "marl_cover", "scripts"])
        finally:
            os.chdir(saved)
    return stdout + stderr, status


if __name__ == "__main__":
    report, code = run_mypy()
    print(report, end="")
    sys.exit(code)
