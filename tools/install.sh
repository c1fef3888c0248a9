#!/usr/bin/env bash
# Installs the CRS stack on a control PC (or into a staging root for a package):
#   binaries  -> $DESTDIR$PREFIX/bin            (motion-core drive-io safety-monitor sim-plant crs)
#   units     -> $DESTDIR/etc/systemd/system    (systemd/*.service, crs-stack.target; ExecStart= points at $PREFIX/bin)
#   helper    -> $DESTDIR$PREFIX/lib/crs/crs-isolation (the stack's namespaces, crs-isolation.service)
#   configs   -> $DESTDIR/etc/crs/config        (a copy of config/; existing files are kept)
#   docs      -> $DESTDIR/etc/crs/systemd/README.md (the units' Documentation=)
#   man pages -> $DESTDIR$PREFIX/share/man/man1 (crs gen-man; DAEMON --gen-man for the daemons)
#   completions -> bash, zsh, fish under $DESTDIR$PREFIX/share
# Usage: tools/install.sh [--prefix /usr/local] [--bin-dir target/release]   (DESTDIR from the environment)
# Without DESTDIR, as root, it also creates the system user `crs` the units run as and reloads
# systemd. It never enables or starts a unit: that stays the operator's decision
# (systemctl enable --now crs-stack.target).
set -euo pipefail
cd "$(dirname "$0")/.."
PREFIX=/usr/local
BIN_DIR=target/release
while [ $# -gt 0 ]; do
  case "$1" in
    --prefix) PREFIX=$2; shift 2 ;;
    --bin-dir) BIN_DIR=$2; shift 2 ;;
    -h|--help) sed -n 2,14p "$0"; exit 0 ;;
    *) echo "install.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done
DESTDIR=${DESTDIR:-}
BINS="motion-core drive-io safety-monitor sim-plant crs"
for b in $BINS; do
  [ -x "$BIN_DIR/$b" ] || { echo "install.sh: $BIN_DIR/$b missing: cargo build --release --workspace --bins" >&2; exit 1; }
done
install -d "$DESTDIR$PREFIX/bin" "$DESTDIR/etc/systemd/system" "$DESTDIR/etc/crs/systemd" "$DESTDIR$PREFIX/lib/crs" \
  "$DESTDIR$PREFIX/share/man/man1" "$DESTDIR$PREFIX/share/bash-completion/completions" \
  "$DESTDIR$PREFIX/share/zsh/site-functions" "$DESTDIR$PREFIX/share/fish/vendor_completions.d"
for b in $BINS; do install -m 0755 "$BIN_DIR/$b" "$DESTDIR$PREFIX/bin/$b"; done
for u in systemd/*.service systemd/*.target; do
  sed "s#/usr/local/\(bin\|lib/crs\)/#$PREFIX/\1/#g" "$u" > "$DESTDIR/etc/systemd/system/$(basename "$u")"
  chmod 0644 "$DESTDIR/etc/systemd/system/$(basename "$u")"
done
install -m 0644 systemd/README.md "$DESTDIR/etc/crs/systemd/README.md"
install -m 0755 systemd/crs-isolation "$DESTDIR$PREFIX/lib/crs/crs-isolation"
# Configs: an operator's edited file is never overwritten.
(cd config && find . -type f) | while read -r f; do
  dst="$DESTDIR/etc/crs/config/${f#./}"
  if [ -e "$dst" ]; then echo "  kept existing $dst"; else install -D -m 0644 "config/$f" "$dst"; fi
done
"$BIN_DIR/crs" gen-man "$DESTDIR$PREFIX/share/man/man1" >/dev/null
for b in motion-core drive-io safety-monitor sim-plant; do
  "$BIN_DIR/$b" --gen-man "$DESTDIR$PREFIX/share/man/man1" >/dev/null
done
"$BIN_DIR/crs" completions bash > "$DESTDIR$PREFIX/share/bash-completion/completions/crs"
"$BIN_DIR/crs" completions zsh > "$DESTDIR$PREFIX/share/zsh/site-functions/_crs"
"$BIN_DIR/crs" completions fish > "$DESTDIR$PREFIX/share/fish/vendor_completions.d/crs.fish"
if [ -z "$DESTDIR" ] && [ "$(id -u)" = 0 ]; then
  id crs >/dev/null 2>&1 || useradd --system --no-create-home --shell /usr/sbin/nologin crs
  command -v systemctl >/dev/null && systemctl daemon-reload 2>/dev/null || true
fi
echo "installed into ${DESTDIR:-/} (prefix $PREFIX); start with: systemctl start crs-stack.target (comes up idle); a ride: crs ride start FILE"
