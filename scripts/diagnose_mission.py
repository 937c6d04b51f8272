"""What mission policies do with their decisions: blind or not, stay, back or forward.

Flies the mission of ``configs/mission.yaml`` (same overrides as ``scripts/run_mission.py``) with
each decentralized method (``greedy``, ``greedy_stay``, ``gnn``), every decision of a ready robot
sorted by whether a point of interest is in its ego-graph and by its move
(:mod:`agents.mission_diagnostics`); ``--blind random|sample|nearest`` replaces the policy's own
blind decisions, to measure what they cost. Prints the points visited per seed and the table of
decisions, and writes them as JSON.

    python scripts/diagnose_mission.py [--blind policy] [--out FILE] [key=value ...]
    e.g.  python scripts/diagnose_mission.py methods=[greedy,gnn] seeds=3
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.cli import write_text_atomic  # noqa: E402
from agents.comparison import sem  # noqa: E402
from agents.configuration import as_dict, load_or_exit  # noqa: E402
from agents.mission import MissionConfig, make_mission_policy, run_mission  # noqa: E402
from agents.mission_diagnostics import BLIND_RULES, KINDS, DecisionRecorder  # noqa: E402

DECENTRALIZED = ("greedy", "greedy_stay", "gnn")


def diagnose(config: MissionConfig, method: str, blind: str) -> dict:
    """Totals per seed and the decision table of ``method`` over the config's seeds."""
    env = config.make_env()
    recorder = DecisionRecorder(make_mission_policy(method, config), env, blind=blind)
    totals = []
    for seed in range(config.seed, config.seed + config.seeds):
        totals.append(run_mission(env, recorder, seed).total)
        print(f"{method:12s} seed {seed:3d}: {totals[-1]:4d} points", flush=True)
    return {"setup": config.setup(method), "totals": totals, "decisions": recorder.table()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", type=Path, default=Path("configs/mission.yaml"))
    parser.add_argument("--blind", choices=BLIND_RULES, default="policy")
    parser.add_argument("--out", type=Path, default=Path("outputs/mission_diagnostics.json"))
    parser.add_argument("overrides", nargs="*", help="key=value, e.g. methods=[greedy,gnn]")
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    config = load_or_exit(MissionConfig, args.config, args.overrides)
    methods = [m for m in config.methods if m in DECENTRALIZED]
    if not methods:
        raise SystemExit(
            f"diagnose_mission: no decentralized method among {config.methods}; "
            f"choose from {DECENTRALIZED}"
        )
    if config.gnn_centralized:
        raise SystemExit("diagnose_mission: gnn_centralized=true; the recorder reads ego-graphs")
    results = {m: diagnose(config, m, args.blind) for m in methods}
    print(f"\nblind decisions: {args.blind}; decisions of ready robots, share of each row")
    print(f"{'method':12s} {'view':8s} {'decisions':>9s} " + "".join(f"{k:>9s}" for k in KINDS))
    for method, result in results.items():
        for view, counts in result["decisions"].items():
            n = sum(counts.values())
            shares = "".join(f"{counts[k] / max(n, 1):9.2f}" for k in KINDS)
            print(f"{method:12s} {view:8s} {n:9d} {shares}")
    print(f"\n{'method':12s} points visited, mean +- SEM over {config.seeds} seeds")
    for method, result in results.items():
        totals = np.array(result["totals"], dtype=float)
        print(f"{method:12s} {totals.mean():.1f} +- {sem(totals):.1f}")
    summary = {"config": as_dict(config), "blind": args.blind, "methods": results}
    write_text_atomic(args.out, json.dumps(summary, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
