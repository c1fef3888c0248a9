#!/usr/bin/env bash
# Builds the Debian package `crs-motion` with dpkg-deb from tools/install.sh's layout (one place
# for where files go), --prefix /usr:
#   /usr/bin                 motion-core drive-io safety-monitor sim-plant crs
#   /usr/lib/systemd/system  the units (ExecStart=/usr/bin/...), crs-stack.target without [Install]
#   /etc/crs/config          the configs: every file under /etc is a conffile, so an edited config
#                            survives an upgrade (dpkg keeps it, or asks)
#   /usr/lib/crs/crs-isolation  the stack's namespaces (crs-isolation.service)
#   /usr/share/man/man1      every binary's man pages, completions (bash, zsh, fish);
#                            /usr/lib/tmpfiles.d/crs.conf (/run/crs)
#   postinst                 the system user and group `crs`, systemd daemon-reload, tmpfiles;
#                            it never enables, starts or restarts a unit (an upgrade leaves a
#                            running stack running: the replaced binaries take effect at the
#                            operator's next start)
# Usage: tools/deb.sh [--bin-dir target/release] [--out target/deb] [--fast] [--version V]
#   --fast: no compression (tests of the package's layout with debug binaries)
#   --version V: the package's version instead of Cargo.toml's (e.g. an upgrade in a test)
# The binaries are stripped of debug info (as Debian packages are). Prints the path of the .deb.
# Needs dpkg-deb and objcopy. The install/upgrade test with dpkg under systemd:
# tools/systemd-boot-test.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN_DIR=target/release
OUT=target/deb
COMPRESS=(-Zxz)
VERSION=
while [ $# -gt 0 ]; do
  case "$1" in
    --bin-dir) BIN_DIR=$2; shift 2 ;;
    --out) OUT=$2; shift 2 ;;
    --fast) COMPRESS=(-Znone); shift ;;
    --version) VERSION=$2; shift 2 ;;
    -h|--help) sed -n 2,20p "$0"; exit 0 ;;
    *) echo "deb.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done
VERSION=${VERSION:-$(sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -1)}
ARCH=$(dpkg --print-architecture)
ROOT="$OUT/crs-motion_${VERSION}_${ARCH}"
rm -rf "$ROOT"
mkdir -p "$ROOT"
DESTDIR="$ROOT" tools/install.sh --prefix /usr --bin-dir "$BIN_DIR" >/dev/null
for b in "$ROOT"/usr/bin/*; do objcopy --strip-debug "$b"; done
# Units belong to the distribution's directory; /etc/systemd/system stays the administrator's.
install -d "$ROOT/usr/lib/systemd/system" "$ROOT/usr/lib/tmpfiles.d" "$ROOT/DEBIAN"
mv "$ROOT"/etc/systemd/system/* "$ROOT/usr/lib/systemd/system/"
rmdir "$ROOT/etc/systemd/system" "$ROOT/etc/systemd"
cat > "$ROOT/usr/lib/tmpfiles.d/crs.conf" <<'TMP'
# The stack's runtime directory (motion-core's control socket lives in /run/crs/motion-core,
# created by its unit's RuntimeDirectory=).
d /run/crs 0755 root root -
TMP
(cd "$ROOT" && find etc -type f | sort | sed 's#^#/#') > "$ROOT/DEBIAN/conffiles"
SIZE=$(du -sk --exclude=DEBIAN "$ROOT" | cut -f1)
cat > "$ROOT/DEBIAN/control" <<CTL
Package: crs-motion
Version: $VERSION
Architecture: $ARCH
Maintainer: crs-motion developers <crs-motion@localhost>
Installed-Size: $SIZE
Depends: libc6, adduser, systemd
Section: science
Priority: optional
Description: control stack of the CableRobot Simulator (cable-driven parallel robot)
 motion-core (1 ms IK + surrogate loop), drive-io (CiA 402 master), safety-monitor
 (independent checks, latched e-stop), sim-plant (simulated drives), and the operator
 command line crs. Starting crs-stack.target moves nothing: rides start on purpose
 (crs ride start FILE). Configs in /etc/crs/config.
CTL
cat > "$ROOT/DEBIAN/postinst" <<'POST'
#!/bin/sh
set -e
if [ "$1" = configure ]; then
  if ! getent passwd crs >/dev/null; then
    adduser --system --group --no-create-home --home /nonexistent crs
  fi
  if [ -d /run/systemd/system ]; then
    systemd-tmpfiles --create /usr/lib/tmpfiles.d/crs.conf || true
    systemctl daemon-reload || true
  fi
fi
# Never enable, start or restart a unit here: starting the stack is the operator's decision,
# and an upgrade must not restart a running stack.
exit 0
POST
cat > "$ROOT/DEBIAN/postrm" <<'POSTRM'
#!/bin/sh
set -e
if [ -d /run/systemd/system ]; then
  systemctl daemon-reload || true
fi
exit 0
POSTRM
chmod 0755 "$ROOT/DEBIAN/postinst" "$ROOT/DEBIAN/postrm"
dpkg-deb --root-owner-group "${COMPRESS[@]}" --build "$ROOT" "$OUT/crs-motion_${VERSION}_${ARCH}.deb" >/dev/null
rm -rf "$ROOT"
echo "$OUT/crs-motion_${VERSION}_${ARCH}.deb"
