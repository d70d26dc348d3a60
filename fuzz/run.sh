#!/usr/bin/env bash
# Runs every cargo-fuzz target for SECONDS each (default 20) from the seed corpus (seed.py) on
# the nightly toolchain, and prints a table of executions and coverage. Fails on a crash: the
# input is in fuzz/artifacts/<target>/; fix it and keep it in fuzz/regressions/<target>/.
# Usage: fuzz/run.sh [SECONDS] [TARGET...]   (CI: .ci/run; docs/reliability.md)
set -euo pipefail
cd "$(dirname "$0")"
secs=${1:-20}
shift || true
server=${BSPVT_SERVER:-../target/debug/bspvt-server}
if [ -x "$server" ]; then python3 seed.py "$server"; else python3 seed.py; fi
# Optimised, with debug assertions and overflow checks (-a: an overflow is a finding), without
# AddressSanitizer (-s none): the code under test has no `unsafe` of its own, and the build
# takes half as long (CI's budget).
flags=(-O -a -s none)
cargo +nightly fuzz build "${flags[@]}"
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then mapfile -t targets < <(cargo +nightly fuzz list); fi
mkdir -p logs
printf '%-11s %10s %8s %14s %9s %7s\n' target execs exec/s "edges covered" features corpus
status=0
for t in "${targets[@]}"; do
  # -timeout: an input slower than 20 s is a finding too; -rss_limit_mb: so is 4 GiB.
  if ! cargo +nightly fuzz run "${flags[@]}" "$t" "corpus/$t" -- -max_total_time="$secs" -max_len=262144 \
      -timeout=20 -rss_limit_mb=4096 -print_final_stats=1 > "logs/$t.log" 2>&1; then
    echo "== fuzz target $t failed; the end of its log (fuzz/logs/$t.log):"
    tail -40 "logs/$t.log"
    status=1
    continue
  fi
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "logs/$t.log")
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "logs/$t.log")
  total=$(sed -n 's/^INFO: Loaded [0-9]* modules *(\([0-9]*\) inline 8-bit counters).*/\1/p' "logs/$t.log" | head -1)
  last=$(grep -E '^#[0-9]+' "logs/$t.log" | tail -1)
  cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$last")
  ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$last")
  corp=$(sed -n 's/.* corp: \([0-9]*\).*/\1/p' <<<"$last")
  printf '%-11s %10s %8s %14s %9s %7s\n' "$t" "$execs" "$rate" "$cov/$total" "$ft" "$corp"
done
exit $status
