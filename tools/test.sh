#!/usr/bin/env bash
# The project's test command (README "Run the tests"; .ci/run calls it).
# Format, lint, unit/integration/property tests on the host, then the HIL tests on real vcan
# inside a QEMU guest when the HIL harness is present.
set -euo pipefail
cd "$(dirname "$0")/.."

echo "== cargo fmt --check"
cargo fmt --all -- --check

echo "== cargo clippy (all targets, -D warnings)"
cargo clippy --workspace --all-targets -- -D warnings

echo "== cargo test (host)"
cargo test --workspace

if [ -f tools/hil-run.sh ] && [ "${CRS_SKIP_HIL:-0}" != 1 ]; then
  echo "== HIL tests on vcan (QEMU guest)"
  bash tools/hil-run.sh
fi
echo "== all tests passed"
