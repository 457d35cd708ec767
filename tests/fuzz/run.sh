#!/usr/bin/env bash
# Runs every fuzz target of a BSN_FUZZ build for a bounded time each, two at a time (BSN_FUZZ_JOBS), on a scratch
# copy of its seed corpus (the repository's corpus is never written).
# Usage: tests/fuzz/run.sh [BUILD_DIR (build-fuzz)] [SECONDS (45)] [TARGET...]
# Exit 1 if any target finds a crash, leak, sanitizer report or broken invariant; its input is kept in
# BUILD_DIR/fuzz-findings/<target>/ (add it to tests/fuzz/corpus/<target>/ as a regression case once fixed).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
build="${1:-build-fuzz}"
seconds="${2:-45}"
shift $(( $# > 2 ? 2 : $# ))
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then mapfile -t targets < "$build/tests/fuzz/targets.txt"; fi
findings="$build/fuzz-findings"
mkdir -p "$findings"
# Two targets at a time (one per core of a CI machine): each has the whole time asked for.
jobs_at_once="${BSN_FUZZ_JOBS:-2}"

fuzz_one() {
  local t="$1" work
  work="$(mktemp -d)"
  cp -r "$here/corpus/$t/." "$work/"
  mkdir -p "$findings/$t"
  # -timeout: one input slower than 10 s is a finding; -rss_limit_mb: so is more than 2 GB.
  if "$build/tests/fuzz/bsn_fuzz_$t" "$work" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
        -max_len=8192 -print_final_stats=1 -artifact_prefix="$findings/$t/" > "$findings/$t.log" 2>&1; then
    echo ok > "$findings/$t.result"
  else
    echo failed > "$findings/$t.result"
  fi
  rm -rf "$work"
}

started=()
for t in "${targets[@]}"; do
  [ -n "$t" ] || continue
  while [ "$(jobs -rp | wc -l)" -ge "$jobs_at_once" ]; do wait -n || true; done
  echo "== fuzz $t for ${seconds} s"
  rm -f "$findings/$t.result"
  fuzz_one "$t" &
  started+=("$t")
done
wait
failed=()
for t in "${started[@]}"; do
  if [ "$(cat "$findings/$t.result" 2>/dev/null)" != ok ]; then
    failed+=("$t")
    echo "== $t: finding"
    tail -40 "$findings/$t.log"
  else
    echo "$t: $(grep -E "stat::number_of_executed_units|stat::new_units_added" "$findings/$t.log" | tr '\n' ' ')"
  fi
done
if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz findings in: ${failed[*]} (inputs in $findings/)" >&2
  exit 1
fi
echo "fuzz: ${#started[@]} targets, no findings"
