#!/usr/bin/env bash
# Trot speed, old against new binary on one noisy machine: runs `oxicat trot --no-plots -q`
# with each binary in turn (old, new, old, new, …), N times each, and prints per run the CPU
# time of the process (user + sys, from /usr/bin/time), the simulated seconds per CPU
# second and the MD5 of the CSV it wrote (both must print the same).
#
#   scripts/trot-speed.sh <old-oxicat> <new-oxicat> [runs, default 5] [extra trot options…]
#
# Keep a copy of the old binary (cp target/release/oxicat /tmp/oxicat-old) before building
# the new one. With `--callgrind` as the first argument each binary runs once under
# callgrind instead and the instruction totals are printed (they do not depend on the
# machine's load).
set -euo pipefail
cg=0
if [ "${1:-}" = "--callgrind" ]; then cg=1; shift; fi
old=$1
new=$2
runs=${3:-5}
shift 2
[ $# -gt 0 ] && shift
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
if [ $cg = 1 ]; then
  for b in "$old" "$new"; do
    ir=$(valgrind --tool=callgrind --callgrind-out-file=/dev/null "$b" trot --no-plots -q \
      --out "$out/cg" "$@" 2>&1 >/dev/null | sed -n 's/.*Collected : \([0-9]*\).*/\1/p')
    echo "$b: $ir instructions, CSV $(md5sum <"$out/cg/trot.csv" | cut -d' ' -f1)"
  done
  exit 0
fi
printf '%-5s %-4s %8s %8s %10s  %s\n' binary run "CPU [s]" "wall [s]" "sim s/CPU s" "trot.csv MD5"
for i in $(seq 1 "$runs"); do
  for which in old new; do
    if [ $which = old ]; then b=$old; else b=$new; fi
    /usr/bin/time -f '%U %S %e' -o "$out/time" "$b" trot --no-plots -q --out "$out/$which" "$@" \
      >"$out/stdout"
    read -r user sys wall <"$out/time"
    sim=$(sed -n 's/^Simulated \([0-9.]*\) s .*/\1/p' "$out/stdout")
    cpu=$(echo "$user + $sys" | bc -l)
    md5=$(md5sum <"$out/$which/trot.csv" | cut -d' ' -f1)
    printf '%-5s %-4s %8.2f %8.2f %10.1f  %s\n' $which "$i" "$cpu" "$wall" \
      "$(echo "$sim / $cpu" | bc -l)" "$md5"
  done
done
