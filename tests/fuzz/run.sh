#!/usr/bin/env bash
# Runs every fuzz target of a BSN_FUZZ build for a bounded time each, on a scratch copy of its seed corpus (the
# repository's corpus is never written). Usage: tests/fuzz/run.sh [BUILD_DIR (build-fuzz)] [SECONDS (45)] [TARGET...]
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
failed=()
for t in "${targets[@]}"; do
  [ -n "$t" ] || continue
  work="$(mktemp -d)"
  cp -r "$here/corpus/$t/." "$work/"
  mkdir -p "$findings/$t"
  echo "== fuzz $t for ${seconds} s"
  # -timeout: one input slower than 10 s is a finding; -rss_limit_mb: so is more than 2 GB.
  if ! "$build/tests/fuzz/bsn_fuzz_$t" "$work" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
        -max_len=8192 -print_final_stats=1 -artifact_prefix="$findings/$t/" > "$findings/$t.log" 2>&1; then
    failed+=("$t")
    tail -40 "$findings/$t.log"
  else
    grep -E "stat::number_of_executed_units|stat::new_units_added" "$findings/$t.log" | tr '\n' ' '
    echo
  fi
  rm -rf "$work"
done
if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz findings in: ${failed[*]} (inputs in $findings/)" >&2
  exit 1
fi
echo "fuzz: ${#targets[@]} targets, no findings"
