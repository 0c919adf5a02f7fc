#!/usr/bin/env bash
# Instructions per call of one variant of a benchmark that has a callgrind mode
# (OXICAT_CALLGRIND=<variant>:<reps>, see crates/*/benches/{pcapng,esi_xml,intel_hex,csv}.rs):
# the bench binary runs the variant R and 2R times under callgrind and the difference of
# the two totals, divided by R, is one call (set-up and process start cancel out).
# Instruction counts do not depend on the load of a shared machine, wall time does.
#
#   scripts/ir-per-call.sh <bench-binary> <variant>... [-- reps]
set -euo pipefail
bin=$1
shift
reps=200
vars=()
while [ $# -gt 0 ]; do
  if [ "$1" = "--" ]; then reps=$2; break; fi
  vars+=("$1")
  shift
done
ir() {
  OXICAT_CALLGRIND="$1:$2" valgrind --tool=callgrind --callgrind-out-file=/dev/null "$bin" 2>&1 |
    sed -n 's/.*Collected : \([0-9]*\).*/\1/p'
}
for v in "${vars[@]}"; do
  a=$(ir "$v" "$reps")
  b=$(ir "$v" $((2 * reps)))
  echo "$v: $(((b - a) / reps)) instructions per call"
done
