"""Command-line plumbing shared by the example planners."""

from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any, List, Optional

import objview
from objview.planner import summary_line


def parse_args(description: str, default_method: str, argv: Optional[List[str]] = None):
    p = argparse.ArgumentParser(description=description)
    p.add_argument(
        "--url",
        default=os.environ.get("OBJVIEW_URL") or "http://127.0.0.1:8080",
        help="server URL (default: $OBJVIEW_URL, else http://127.0.0.1:8080)",
    )
    p.add_argument(
        "--token",
        default=os.environ.get("OBJVIEW_TOKEN") or None,
        help="bearer token of a server started with --tokens (default: $OBJVIEW_TOKEN)",
    )
    p.add_argument(
        "--split",
        default=None,
        help="split id (GET /v1/splits; default: main-hidden-test or main_hidden_test when the "
        "server has it, else its first split)",
    )
    p.add_argument(
        "--objects",
        default=None,
        help="comma-separated object indices or uids of the split (default: all)",
    )
    p.add_argument("--space", default="whole", help="view space: whole, hemi, quarter, eighth")
    p.add_argument("--budget", default="auto", help="K (planner views after the start) or auto")
    p.add_argument("--candidates", default="tammes-360", help="candidate set")
    p.add_argument("--seed", type=int, default=0, help="base seed")
    p.add_argument("--method", default=default_method, help="method name recorded by the server")
    p.add_argument("--no-timings", action="store_true", help="record 0 for every wall-clock time")
    p.add_argument("--out", default=None, help="write the results as JSON Lines here")
    p.add_argument("--quiet", action="store_true", help="no per-episode lines")
    return p.parse_args(argv)


def parse_objects(s: Optional[str]) -> Optional[List[Any]]:
    if s is None:
        return None
    out: List[Any] = []
    for part in s.split(","):
        part = part.strip()
        if part:
            out.append(int(part) if part.isdigit() else part)
    return out


def parse_budget(s: str) -> Any:
    return int(s) if str(s).isdigit() else s


def pick_split(client: objview.Client, split: Optional[str]) -> str:
    if split is not None:
        return split
    ids = [s["id"] for s in client.splits()]
    for name in ("main-hidden-test", "main_hidden_test"):
        if name in ids:
            return name
    if not ids:
        raise SystemExit("the server has no splits")
    return ids[0]


def main(planner: Any, args) -> List[dict]:
    client = objview.Client(args.url, token=args.token)
    split = pick_split(client, args.split)
    results = objview.run_planner(
        client,
        planner,
        split,
        objects=parse_objects(args.objects),
        view_space=args.space,
        budget=parse_budget(args.budget),
        method=args.method,
        candidate_set=args.candidates,
        seed=args.seed,
        params=getattr(planner, "params", None),
        record_timings=not args.no_timings,
        eager_depth=False,  # these planners never read the depth images
        progress=(lambda i, r: print(summary_line(r), flush=True)) if not args.quiet else None,
    )
    if args.out:
        with open(args.out, "w", encoding="utf-8") as f:
            for r in results:
                f.write(json.dumps(r) + "\n")
    print(f"{len(results)} episodes finished", file=sys.stderr)
    return results
