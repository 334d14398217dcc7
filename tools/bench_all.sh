#!/usr/bin/env bash
# Run every registered benchmark once, side by side on this machine, and collect the tables in one file.
#   tools/bench_all.sh [OUT.md] [--quick] [--only NAME,...] [--skip NAME,...]
#       (default OUT: out/bench/all.md; the documented runs take about half an hour on 2 cores, --quick a few minutes)
# The list comes from the one registry, robofabric/bench/__init__.py (`robofabric bench list`); each benchmark
# runs with the arguments quoted in docs/benchmarks.md. Rerun them on your own machine before comparing, and
# compare medians and ratios from one run, not numbers from different days.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=out/bench/all.md
if [[ $# -gt 0 && $1 != -* ]]; then OUT=$1; shift; fi
RF=${ROBOFABRIC:-.venv/bin/robofabric}
exec "$RF" bench all --out "$OUT" "$@"
