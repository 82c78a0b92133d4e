#!/usr/bin/env bash
# Output-stability check for refactors: runs a fixed set of commands with one objview binary
# into OUT (annotate, pool split, run --no-timings for every classical planner in two view spaces and
# budgets, report --no-plots) with timing fields that vary by design removed, so that two
# binaries can be compared with `diff -r OUT_A OUT_B`:
#
#   bash scripts/golden.sh path/to/objview-before /tmp/golden-before
#   bash scripts/golden.sh target/ci/objview        /tmp/golden-after
#   diff -r /tmp/golden-before /tmp/golden-after && echo identical
#
# Objects: six built-in objects whose exact d_plan is proved well within the generous time limit
# (the torus takes the longest: ~8M search nodes, a minute on an idle core), so the annotation
# does not depend on machine load. About 2 minutes on 2 cores.
set -euo pipefail
bin="$(realpath "$1")"
rm -rf "$2"
mkdir -p "$2"
out="$(realpath "$2")"
# Everything runs inside a scratch folder with relative paths, so that no output names a
# temporary path.
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cd "$work"
objs="sphere cube torus cup mug l-shape"
"$bin" objects synth --out all >/dev/null
mkdir -p objs res
for o in $objs; do cp "all/$o.obj" objs/; done
# Annotation: timings (seconds fields) are wall-clock; everything else must match.
"$bin" annotate objs --out annotations.jsonl --threads 2 --time-limit 1000 >/dev/null 2>&1
python3 - annotations.jsonl "$out/annotations.jsonl" <<'PY'
import json, sys
def strip(v):
    if isinstance(v, dict):
        return {k: strip(x) for k, x in v.items() if not (k.endswith("_s") or k.endswith("seconds") or k in ("elapsed", "timings", "created", "host"))}
    if isinstance(v, list):
        return [strip(x) for x in v]
    return v
with open(sys.argv[1]) as f, open(sys.argv[2], "w") as g:
    lines = [json.loads(l) for l in f if l.strip()]
    lines.sort(key=lambda v: v.get("uid", ""))
    for v in lines:
        g.write(json.dumps(strip(v), sort_keys=True) + "\n")
PY
export XDG_CACHE_HOME="$work/cache"
for space in whole quarter; do
  for spec in "random-tsp 5" "random-tsp 30" "rse auto" "rse-mov auto" "random auto" "oracle auto"; do
    set -- $spec
    "$bin" run --planner "$1" --budget "$2" --space "$space" --objects objs \
      --out "res/run-$1-$2-$space.jsonl" --no-timings --threads 2 --seed 3 --quiet >/dev/null
  done
done
"$bin" report res/run-*.jsonl --out res/report --no-plots >/dev/null
cp -r res/. "$out/"
