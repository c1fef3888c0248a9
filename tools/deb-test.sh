#!/usr/bin/env bash
# Checks the Debian package tools/deb.sh builds (its layout, on the host; the install/upgrade
# test with dpkg under systemd is tools/systemd-boot-test.sh): binaries in /usr/bin, units in
# /usr/lib/systemd/system starting /usr/bin/..., motion-core's unit idle with its control
# socket, the isolation helper, every config of config/ a conffile under /etc/crs/config, the
# man pages of every binary (rendered by `man -l`), completions, tmpfiles, and maintainer
# scripts that never enable, start or restart a unit.
# Usage: tools/deb-test.sh [--bin-dir target/debug]   (uncompressed package, removed after)
set -euo pipefail
cd "$(dirname "$0")/.."
BIN_DIR=${2:-target/debug}
[ "${1:-}" = --bin-dir ] || BIN_DIR=target/debug
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
DEB=$(tools/deb.sh --bin-dir "$BIN_DIR" --out "$OUT" --fast)
fail() { echo "DEB-TEST: FAIL: $*" >&2; exit 1; }
LIST=$(dpkg-deb -c "$DEB" | awk '{print $6}')
for b in motion-core drive-io safety-monitor sim-plant crs; do
  grep -qx "./usr/bin/$b" <<<"$LIST" || fail "no /usr/bin/$b"
done
X="$OUT/x"; mkdir "$X"; dpkg-deb -x "$DEB" "$X"; dpkg-deb -e "$DEB" "$X/DEBIAN"
for u in crs-motion-core crs-drive-io crs-safety-monitor; do
  grep -q "^ExecStart=/usr/bin/" "$X/usr/lib/systemd/system/$u.service" || fail "$u: ExecStart not /usr/bin"
done
grep -q -- "--control /run/crs/motion-core/control.sock" "$X/usr/lib/systemd/system/crs-motion-core.service" \
  || fail "motion-core's unit does not come up idle with its control socket"
grep -q '^\[Install\]' "$X/usr/lib/systemd/system/crs-stack.target" && fail "crs-stack.target has [Install]"
[ -d "$X/etc/systemd" ] && fail "units under /etc/systemd (the administrator's directory)"
N_CFG=$(cd config && find . -type f | wc -l)
N_CONF=$(grep -c '^/etc/crs/config/' "$X/DEBIAN/conffiles")
[ "$N_CFG" = "$N_CONF" ] || fail "$N_CFG configs but $N_CONF conffiles under /etc/crs/config"
grep -qx /etc/crs/config/motion-core.toml "$X/DEBIAN/conffiles" || fail "motion-core.toml not a conffile"
[ -f "$X/usr/share/man/man1/crs-ride-start.1" ] || fail "no man page crs-ride-start.1"
command -v man >/dev/null || { apt-get install -y -qq --no-install-recommends man-db >/dev/null 2>&1 || true; }
for page in crs motion-core drive-io safety-monitor safety-monitor-reset safety-monitor-accept sim-plant; do
  f="$X/usr/share/man/man1/$page.1"
  [ -f "$f" ] || fail "no man page $page.1"
  # The page renders (groff via man -l) and names its program and an option.
  txt=$(MANWIDTH=80 man -l "$f" 2>&1) || fail "man -l $page.1: $txt"
  grep -q "^NAME" <<<"$txt" && grep -q -- "$page" <<<"$txt" && grep -q -- "--" <<<"$txt" ||
    fail "man -l $page.1 renders no NAME/options: $(head -5 <<<"$txt")"
done
[ -x "$X/usr/lib/crs/crs-isolation" ] || fail "no /usr/lib/crs/crs-isolation"
grep -q '^ExecStart=/usr/lib/crs/crs-isolation start' "$X/usr/lib/systemd/system/crs-isolation.service" ||
  fail "crs-isolation.service does not start /usr/lib/crs/crs-isolation"
[ -f "$X/usr/share/bash-completion/completions/crs" ] || fail "no bash completion"
grep -q '^d /run/crs ' "$X/usr/lib/tmpfiles.d/crs.conf" || fail "no tmpfiles entry"
grep -q 'adduser --system --group' "$X/DEBIAN/postinst" || fail "postinst creates no user crs"
if grep -Eq 'systemctl +(start|restart|try-restart|reload-or-restart|enable)|deb-systemd-invoke' \
  "$X/DEBIAN/postinst" "$X/DEBIAN/postrm"; then
  fail "a maintainer script starts, restarts or enables a unit"
fi
N_MAN=$(grep -c '^\./usr/share/man/man1/.*\.1$' <<<"$LIST")
echo "DEB-TEST: PASS ($(basename "$DEB"): $(grep -c . <<<"$LIST") entries, $N_CONF conffiles, $N_MAN man pages)"
