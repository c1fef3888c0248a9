#!/bin/bash
# usage: tools/safety-hil-old-binaries.sh OLD_BIN_DIR [safety-hil options, e.g. --only jump_from_rest]
#   Runs THIS tree's safety-hil scenarios (target/debug/safety-hil, the host's wire model)
#   against the safety-monitor, drive-io and motion-core of an older build in OLD_BIN_DIR (e.g.
#   a debug build of the commit before the review's holes were closed, see
#   docs/safety-monitor.md "The review's holes on the old code"). The harness's test rig stays
#   this tree's: the winch emulator (drives, load cells, safety I/O node), the can-wire hub and
#   the fault injection.
#   The generated configs carry keys the old binaries do not know; wrappers in a temporary
#   bin dir give each old binary a copy of its --config without them (the monitor's
#   [can] safety_io_silence_cycles and [reset] section) and exec it, so the process is the
#   old binary itself (the monitor's stream-owner check reads /proc/<pid>/exe). Nothing of this
#   is in a product binary or in safety-hil.
# Prints safety-hil's output; exit status is safety-hil's (FAIL is the expected outcome for
# a hole the old code has).
set -euo pipefail
cd "$(dirname "$0")/.."
OLD=$(cd "${1:?usage: $0 OLD_BIN_DIR [safety-hil options]}" && pwd); shift
NEW=$(pwd)/${CARGO_TARGET_DIR:-target}/debug
BIN=$(mktemp -d); W=$(mktemp -d); chmod 755 "$W"
trap 'rm -rf "$BIN"' EXIT
for b in winch-emulator can-wire safety-monitor-nmt-unsent; do ln -s "$NEW/$b" "$BIN/$b"; done
# One wrapper per old binary: rewrite --config F into F's directory as <name>.old.toml.
for b in safety-monitor drive-io motion-core; do
  cat > "$BIN/$b" <<WRAP
#!/bin/bash
args=()
while [ \$# -gt 0 ]; do
  if [ "\$1" = --config ]; then
    c=\$2; o=\${c%.toml}.old.toml
    sed -e '/^safety_io_silence_cycles *=/d' -e 's/^reader_stall_cycles *=.*/reader_stall_cycles = 67/' -e '/^\[reset\]/,/^\[/{/^\[reset\]/d;/^\[/!d}' "\$c" > "\$o"
    args+=(--config "\$o"); shift 2
  else
    args+=("\$1"); shift
  fi
done
exec -a "$b" "$OLD/$b" "\${args[@]}"
WRAP
  chmod +x "$BIN/$b"
done
echo "safety-hil (this tree) against $OLD: safety-monitor, drive-io, motion-core; workdir $W"
"$NEW/safety-hil" --bin-dir "$BIN" --workdir "$W" "$@"
