#!/bin/bash
# usage: tools/safety-mutants.sh [NAME...]      (default: every tests/safety-mutants/*.patch)
#
# Evidence that each review scenario of safety-hil (docs/safety-evidence.md) fails without
# the fix it tests, for the reason the review gave, and passes with it. In a scratch worktree
# of this commit (detached HEAD, its own target dir seeded once from this tree's target/debug):
#   1. the unpatched tree: builds the bins, runs `safety-hil --only NAME` (host run, spec
#      timing asserted), requires PASS;
#   2. per mutant tests/safety-mutants/NAME.patch (a minimal patch taking the fix out of the
#      product code): applies it, builds the bins, runs the same command and requires a FAIL
#      line for NAME, after the fault was injected, matching the patch's `Expect:` regex (the
#      review's cause); runs each `Unit-test:` of the patch header and requires it to FAIL;
#      reverts the patch.
# Prints one `SAFETY-MUTANT OK|BAD NAME: ...` line per scenario and the harness's PASS and FAIL
# lines; full output in $SCR/logs/. Exit status 0 only if every expectation held.
# Runs one scenario at a time (the host matrix is timing-sensitive: run it on a quiet machine;
# a mutant run that only stalls before its fault is reported BAD, not as evidence).
# Not part of tools/test.sh: about 3-5 min per scenario (builds dominate).
#
# Patch header (text before the first `diff --git`, ignored by git apply):
#   Expect: <extended regex the harness's FAIL line must match>
#   Scenario: none   (no safety-hil scenario covers it: only the unit tests, which must fail)
#   Unit-test: <cargo test arguments selecting one test that must FAIL under the mutant>
#
# Environment: SAFETY_MUTANTS_DIR (scratch, default target/safety-mutants; delete it to
# reclaim the disk), SAFETY_HIL_ARGS (default "--assert-timing --attempts 2 --retry-budget 2").
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
export CARGO_INCREMENTAL=0
SCR=${SAFETY_MUTANTS_DIR:-$ROOT/target/safety-mutants}
HIL_ARGS=${SAFETY_HIL_ARGS:---assert-timing --attempts 2 --retry-budget 2}
BINS=(--bin safety-monitor --bin drive-io --bin motion-core --bin winch-emulator --bin can-wire
      --bin safety-hil --bin safety-monitor-nmt-unsent)

if [ $# -eq 0 ]; then
  set -- $(ls tests/safety-mutants/*.patch | xargs -n1 basename | sed 's/\.patch$//')
fi
for n in "$@"; do
  [ -f "tests/safety-mutants/$n.patch" ] || { echo "no tests/safety-mutants/$n.patch" >&2; exit 2; }
done

mkdir -p "$SCR/logs"
TREE=$SCR/tree
if [ ! -e "$TREE/.git" ]; then
  git worktree add --detach "$TREE" HEAD >/dev/null || exit 2
fi
git -C "$TREE" checkout -q --detach "$(git rev-parse HEAD)" && git -C "$TREE" reset -q --hard \
  && git -C "$TREE" clean -qfd || exit 2
export CARGO_TARGET_DIR=$SCR/target
if [ ! -d "$CARGO_TARGET_DIR/debug" ] && [ -d "$ROOT/target/debug" ]; then
  # The dependencies are path-independent; this tree's own crates rebuild once.
  mkdir -p "$CARGO_TARGET_DIR" && cp -a "$ROOT/target/debug" "$CARGO_TARGET_DIR/debug"
fi

build() { (cd "$TREE" && nice -n 10 cargo build -q "${BINS[@]}") >"$1" 2>&1; }
hil() {  # BIN_DIR NAME LOG -> the harness's output in LOG
  local w; w=$(mktemp -d); chmod 755 "$w"
  # shellcheck disable=SC2086
  "$1/safety-hil" --bin-dir "$1" --workdir "$w" $HIL_ARGS --only "$2" >"$3" 2>&1
  rm -rf "$w"
}
line() { grep -m1 -E "^SAFETY-HIL (PASS|FAIL) $1:" "$2" || echo "(no PASS/FAIL line for $1)"; }

bad=0
T0=$(date +%s)
echo "safety-mutants at $(git rev-parse --short HEAD), scratch $SCR, safety-hil $HIL_ARGS"
if ! build "$SCR/logs/build-unpatched.log"; then
  echo "SAFETY-MUTANT BAD: the unpatched tree does not build ($SCR/logs/build-unpatched.log)"
  exit 1
fi
# The unpatched bins, kept for every scenario's unpatched run.
UNPATCHED=$SCR/bin-unpatched
rm -rf "$UNPATCHED" && mkdir -p "$UNPATCHED"
for b in "${BINS[@]}"; do [ "$b" = --bin ] || cp "$CARGO_TARGET_DIR/debug/$b" "$UNPATCHED/"; done
for n in "$@"; do
  p=$ROOT/tests/safety-mutants/$n.patch
  expect=$(sed -n 's/^Expect: //p' "$p" | head -1)
  scenario=$(sed -n 's/^Scenario: //p' "$p" | head -1)
  t=$(date +%s)
  ok=1; why=""
  if [ "$scenario" != none ]; then
    # 1. Unpatched: PASS.
    hil "$UNPATCHED" "$n" "$SCR/logs/$n.unpatched.log"
    pass=$(line "$n" "$SCR/logs/$n.unpatched.log")
    echo "  unpatched: $pass"
    case $pass in "SAFETY-HIL PASS $n:"*) ;; *) ok=0; why="unpatched tree did not PASS; ";; esac
  fi
  # 2. The mutant: FAIL for the expected cause, and its unit tests fail.
  if ! git -C "$TREE" apply "$p"; then
    echo "SAFETY-MUTANT BAD $n: the patch does not apply"; bad=1; continue
  fi
  if [ "$scenario" = none ]; then
    : # no scenario covers it: the unit tests are the evidence.
  elif ! build "$SCR/logs/$n.build.log"; then
    echo "SAFETY-MUTANT BAD $n: the mutant does not build ($SCR/logs/$n.build.log)"
    git -C "$TREE" checkout -q -- . ; bad=1; continue
  fi
  if [ "$scenario" != none ]; then
    hil "$CARGO_TARGET_DIR/debug" "$n" "$SCR/logs/$n.mutant.log"
    fail=$(line "$n" "$SCR/logs/$n.mutant.log")
    echo "  mutant:    $fail"
    case $fail in
      "SAFETY-HIL FAIL $n:"*"after the fault was injected"*) ;;
      *) ok=0; why+="mutant did not FAIL after the fault was injected; ";;
    esac
    echo "$fail" | grep -qE -- "$expect" || { ok=0; why+="FAIL line does not match /$expect/; "; }
  fi
  tests=""
  : >"$SCR/logs/$n.unit.log"
  while IFS= read -r ut; do
    [ -n "$ut" ] || continue
    u=$SCR/logs/$n.unit-${ut##* }.log
    # shellcheck disable=SC2086
    if (cd "$TREE" && nice -n 10 cargo test -q $ut) >"$u" 2>&1; then
      ok=0; why+="unit test passed under the mutant: ${ut##* }; "
    elif grep -q "panicked at" "$u"; then
      tests+="unit test ${ut##* } fails; "
    else
      ok=0; why+="unit test did not run: $ut ($u); "
    fi
    cat "$u" >>"$SCR/logs/$n.unit.log"
  done < <(sed -n 's/^Unit-test: //p' "$p")
  git -C "$TREE" checkout -q -- .
  s=$(( $(date +%s) - t ))
  if [ "$scenario" = none ] && [ -z "$tests" ]; then
    ok=0; why+="no scenario and no unit test failed; "
  fi
  if [ $ok = 1 ] && [ "$scenario" = none ]; then
    echo "SAFETY-MUTANT OK $n: (no scenario) ${tests}(${s} s)"
  elif [ $ok = 1 ]; then
    echo "SAFETY-MUTANT OK $n: unpatched PASS, mutant FAIL matching /$expect/; ${tests}(${s} s)"
  else
    echo "SAFETY-MUTANT BAD $n: ${why}${tests}(${s} s; logs $SCR/logs/$n.*)"; bad=1
  fi
done
echo "safety-mutants: $# scenario(s), $(( $(date +%s) - T0 )) s, $([ $bad = 0 ] && echo ALL OK || echo SOME BAD)"
exit $bad
