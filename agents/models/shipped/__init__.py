"""Models shipped with the library, one per task, each with a JSON card beside it.

The card (``<task>_gnn.json``) records the command, seed, dataset and scores that made the model.
"""

from __future__ import annotations

from pathlib import Path

SHIPPED = Path(__file__).resolve().parent


def shipped_model_path(task: str = "coverage") -> Path:
    """The shipped model file of ``task``.

    Raises:
        FileNotFoundError: no model is shipped for ``task``, naming the tasks that have one.
    """
    path = SHIPPED / f"{task}_gnn.pt"
    if not path.is_file():
        available = sorted(p.name.removesuffix("_gnn.pt") for p in SHIPPED.glob("*_gnn.pt"))
        raise FileNotFoundError(f"no shipped model for task {task!r}; shipped: {available}")
    return path
