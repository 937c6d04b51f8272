"""What the training commands share: a run, its errors in one line, its summary as JSON."""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from typing import Any, TypeVar

T = TypeVar("T")


def run_training(prog: str, train: Callable[[T], dict[str, Any]], config: T) -> dict[str, Any]:
    """``train(config)``, its summary printed as JSON.

    Raises:
        SystemExit: a bad setting or a missing file, in one line that names the command.
    """
    logging.basicConfig(level=logging.WARNING)
    import torchrl  # noqa: F401 (configures its logger on import; quieten it after)

    logging.getLogger("torchrl").setLevel(logging.WARNING)  # it logs buffer set-up to stdout
    try:
        summary = train(config)
    except (ValueError, FileNotFoundError) as error:
        raise SystemExit(f"{prog}: {error}") from None
    print(json.dumps(summary, indent=2, default=str))
    return summary
