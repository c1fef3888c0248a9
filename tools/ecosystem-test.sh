#!/usr/bin/env bash
# The ecosystem's own tools on what the stack writes:
#  - a `crs sim` run with drive-io's candump log: python-can reads every line, can-utils'
#    log2asc converts every frame (canplayer replays it where the kernel has CAN);
#  - the run's logs are plain text (no ANSI escapes) and its plots + index.html exist;
#  - man pages (crs gen-man) render with man(1), completions (crs completions) load in bash;
#  - tools/install.sh into a DESTDIR stages binaries, units (verified), configs, man, completions.
# Uses the static release binaries the HIL scripts build. Env: ECO_BIN_DIR for other binaries.
set -euo pipefail
cd "$(dirname "$0")/.."
export DEBIAN_FRONTEND=noninteractive
command -v log2asc >/dev/null || { apt-get update -qq >/dev/null && apt-get install -y -qq can-utils >/dev/null; }
python3 -c "import can" 2>/dev/null || pip install -q python-can >/dev/null
if [ -z "${ECO_BIN_DIR:-}" ]; then
  TRIPLE=x86_64-unknown-linux-gnu
  RUSTFLAGS="-C target-feature=+crt-static" cargo build --profile release --target "$TRIPLE" \
    --workspace --bin crs --bin motion-core --bin drive-io --bin sim-plant --bin safety-monitor
  ECO_BIN_DIR=${CARGO_TARGET_DIR:-target}/$TRIPLE/release
fi
BIN=$ECO_BIN_DIR
OUT=out/ecosystem
rm -rf "$OUT"; mkdir -p "$OUT"

echo "-- crs sim with a candump log"
LOG=$(pwd)/$OUT/bus.candump
# (the copy lives elsewhere: its EDS paths, relative to the file, made absolute)
sed -e "s#^\# candump_log = .*#candump_log = \"$LOG\"#" -e "s#^eds = \"eds/#eds = \"$PWD/config/eds/#" \
  config/drives.toml > "$OUT/drives.toml"
grep -q "^candump_log" "$OUT/drives.toml" || { echo "could not enable candump_log in the drives copy"; exit 1; }
# --timing relaxed (4 ms loop and SYNC, watchdogs to match): this checks what the tools read in
# a run's files, not the host's timing; at the spec's 1 ms / 10 ms a stall of this shared host
# stops the bus in about one run of six (README), which would fail this check for nothing it tests.
# The tour ends at home: 0.20 / 0.33 mm at rest seen (relaxed runs), the bound 2 mm.
"$BIN/crs" sim --bin-dir "$BIN" --drives "$OUT/drives.toml" --timing relaxed --out "$OUT/sim" --check --max-static-error-mm 2 > "$OUT/crs-sim.txt" 2>&1 \
  || { tail -30 "$OUT/crs-sim.txt"; exit 1; }
N=$(grep -c '^(' "$LOG")
[ "$N" -gt 1000 ] || { echo "candump log has only $N lines"; exit 1; }
echo "  $N frames logged by drive-io"

echo "-- python-can reads it"
python3 - "$LOG" "$N" <<'PY'
import can, sys
msgs = list(can.CanutilsLogReader(sys.argv[1]))
n = int(sys.argv[2])
assert len(msgs) == n, f"python-can read {len(msgs)} of {n} frames"
ids = {m.arbitration_id for m in msgs}
assert 0x080 in ids, "no SYNC (0x080) in the log"
assert any(0x181 <= i <= 0x1FF for i in ids), "no TPDO1 of a drive"
assert any(0x201 <= i <= 0x27F for i in ids), "no RPDO1 to a drive"
# One writer per interface appends whole lines to the file: each interface's lines are in
# time order (the file as a whole interleaves their buffers).
chans = {}
for m in msgs:
    chans.setdefault(m.channel, []).append(m.timestamp)
assert len(chans) >= 4, f"frames of {sorted(chans)} only (the shipped layout has four drive buses)"
for c, t in chans.items():
    assert all(b >= a for a, b in zip(t, t[1:])), f"{c}: timestamps not monotonic"
t = sorted(m.timestamp for m in msgs)
print(f"  python-can: {len(msgs)} frames on {len(chans)} interfaces, {len(ids)} ids, {t[-1]-t[0]:.1f} s")
PY

echo "-- can-utils log2asc converts every frame"
IFACE=$(awk 'NR==1 && /^\(/{print $2}' "$LOG"); [ -n "$IFACE" ] || IFACE=$(grep -m1 '^(' "$LOG" | awk '{print $2}')
# Every interface in the log (the shipped layout logs five).
IFACES=$(awk '/^\(/{print $2}' "$LOG" | sort -u)
# shellcheck disable=SC2086
log2asc -I "$LOG" -O "$OUT/bus.asc" $IFACES
A=$(grep -cE '^ +[0-9]+\.[0-9]+ [0-9]+ ' "$OUT/bus.asc")
[ "$A" -eq "$N" ] || { echo "log2asc wrote $A frames of $N"; exit 1; }
echo "  log2asc: $A frames in $OUT/bus.asc"
if ip link show vcan0 >/dev/null 2>&1; then
  canplayer -t -I "$LOG" "vcan0=$IFACE" && echo "  canplayer replayed it on vcan0"
else
  echo "  canplayer: skipped (this kernel has no CAN; it needs a CAN socket even to print)"
fi

echo "-- the run's logs are plain text, its plots exist"
if grep -l $'\x1b\[' "$OUT"/sim/*.log; then echo "ANSI escape codes in the logs above"; exit 1; fi
for f in pose.svg forces.svg loop.svg events.svg index.html summary.json; do
  [ -s "$OUT/sim/$f" ] || { echo "missing $OUT/sim/$f"; exit 1; }
done
grep -q 'pose.svg' "$OUT/sim/index.html"
echo "  $(ls "$OUT"/sim/*.log | wc -l) logs without escapes; plots and index.html written"

echo "-- man pages and completions"
# Producers write to files and grep reads the files: `producer | grep -q` under pipefail fails
# at random when grep exits before the producer has written everything (SIGPIPE / EPIPE).
"$BIN/crs" --help > "$OUT/help.txt"
grep -q "console" "$OUT/help.txt"
"$BIN/crs" gen-man "$OUT/man" > "$OUT/gen-man.txt"
grep -q "man pages" "$OUT/gen-man.txt"
for p in crs crs-sim crs-console crs-model-ik; do
  [ -s "$OUT/man/$p.1" ] || { echo "missing man page $p.1"; exit 1; }
done
MANWIDTH=100 man -l "$OUT/man/crs-sim.1" >"$OUT/crs-sim.man.txt" 2>"$OUT/man-warnings.txt"
grep -q -- "--console" "$OUT/crs-sim.man.txt"
[ ! -s "$OUT/man-warnings.txt" ] || { cat "$OUT/man-warnings.txt"; exit 1; }
"$BIN/crs" completions bash > "$OUT/crs.bash"
bash -c "source '$OUT/crs.bash' && complete -p crs" > "$OUT/complete-p.txt"
grep -q "crs" "$OUT/complete-p.txt"
"$BIN/crs" completions zsh > "$OUT/crs.zsh"
grep -q "#compdef crs" "$OUT/crs.zsh"
"$BIN/crs" completions fish > "$OUT/crs.fish"
grep -q "complete -c crs" "$OUT/crs.fish"
# An early-closing reader is not a crash (clap_complete panics on a failed write; crs must not).
"$BIN/crs" completions zsh 2>"$OUT/completions-pipe.err" | head -c 1 >/dev/null || true
if grep -q "panicked" "$OUT/completions-pipe.err"; then cat "$OUT/completions-pipe.err"; exit 1; fi
echo "  $(ls "$OUT"/man | wc -l) man pages render; bash/zsh/fish completions generated"

echo "-- tools/install.sh into a DESTDIR"
DEST=$(pwd)/$OUT/destdir
DESTDIR="$DEST" bash tools/install.sh --prefix /usr --bin-dir "$BIN" >/dev/null
for f in usr/bin/motion-core usr/bin/crs etc/systemd/system/crs-stack.target \
         etc/systemd/system/crs-motion-core.service etc/crs/config/motion-core.toml \
         usr/share/man/man1/crs.1 usr/share/bash-completion/completions/crs; do
  [ -e "$DEST/$f" ] || { echo "install.sh did not install $f"; exit 1; }
done
grep -q "ExecStart=/usr/bin/motion-core" "$DEST/etc/systemd/system/crs-motion-core.service"
echo "  staged: $(find "$DEST" -type f | wc -l) files; units point at /usr/bin"
echo "ECOSYSTEM-TEST: PASS"
