#!/usr/bin/env bash
# Run every benchmark once, side by side on this machine, and collect the tables in one file.
#   tools/bench_all.sh [OUT.md]        (default: out/bench/all.md; about 10 minutes on 2 cores)
# The figures quoted in docs/benchmarks.md come from these commands; rerun them on your own machine
# before comparing, and compare medians and ratios from one run, not numbers from different days.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-out/bench/all.md}
RF=${ROBOFABRIC:-.venv/bin/robofabric}
mkdir -p "$(dirname "$OUT")"
{
  echo "# robofabric benchmarks, $(date -u +%Y-%m-%dT%H:%MZ)"
  echo
  echo "Machine: $(uname -m), $(nproc) CPUs, $(python3 --version 2>&1), git $(git rev-parse --short HEAD 2>/dev/null || echo '?')"
  echo
} > "$OUT"
run() { echo "== robofabric bench $*" >&2; "$RF" bench "$@"; }
run transport --out "$OUT"
run sim --out "$OUT.sim" && cat "$OUT.sim" >> "$OUT" && rm -f "$OUT.sim"
run ik --out "$OUT"
run nav --out "$OUT"
run ownership | tee -a "$OUT"
run failover --kills 10 --out "$OUT.failover" && cat "$OUT.failover" >> "$OUT" && rm -f "$OUT.failover"
run record --out "$OUT"
echo "wrote $OUT" >&2
