#!/bin/bash
# usage: tools/vcan-vm.sh TEST_BIN [ARG...]
#   Boots Debian's stock kernel (has can.ko, can-raw.ko, vcan.ko) in QEMU with vcan0..vcan3 up
#   and runs TEST_BIN (a static x86_64 binary, or a dynamic one: its libraries are copied in)
#   with ARGs as /tests/TEST_BIN. Exit status 0 iff the binary exited 0.
#
# Why: CI hosts often run kernels without CAN (CONFIG_CAN unset: SocketCAN opens fail with
# ENODEV/EAFNOSUPPORT), and containers cannot load modules. QEMU runs unprivileged.
#
# Self-installing: installs qemu-system-x86 + busybox-static with apt-get (needs root or sudo)
# and downloads the kernel package with `apt-get download` (no other network access).
# Env: CRS_VCAN_CACHE  cache dir for the kernel + modules (default ~/.cache/crs-vcan-vm)
#      VCAN_TIMEOUT    seconds before QEMU is killed (default 600)
#      VCAN_ACCEL      tcg|kvm (default: kvm only if /dev/kvm is writable AND cpuinfo has vmx/svm;
#                      some nested /dev/kvm implementations cannot boot Debian kernels)
#      VCAN_MEM        guest memory MiB (default 512)
#      VCAN_EXTRA_BINS space-separated extra executables copied to the guest's /bin (on PATH, not
#                      run as tests): the processes a multi-process test spawns
#      VCAN_DATA       space-separated files/dirs (relative to the current directory) copied to
#                      the guest's /work, which becomes the test's working directory
# Timing inside the guest is emulated (TCG): assert behaviour there, never latency.
set -euo pipefail
[ $# -ge 1 ] || { echo "usage: $0 TEST_BIN [ARG...]" >&2; exit 2; }
BIN=$1; shift
[ -x "$BIN" ] || { echo "vcan-vm: $BIN is not an executable file" >&2; exit 2; }
C=${CRS_VCAN_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/crs-vcan-vm}; mkdir -p "$C"
SUDO=; [ "$(id -u)" = 0 ] || SUDO=sudo
if ! command -v qemu-system-x86_64 >/dev/null || [ ! -x /bin/busybox ]; then
  echo "vcan-vm: installing qemu-system-x86 busybox-static" >&2
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends \
    qemu-system-x86 busybox-static >/dev/null
fi
if [ ! -s "$C/vmlinux" ] || [ ! -s "$C/vcan.ko" ]; then
  echo "vcan-vm: fetching the Debian kernel package into $C" >&2
  PKG=$(apt-cache depends linux-image-amd64 | awk '/Depends: linux-image-[0-9]/{print $2; exit}')
  [ -n "$PKG" ] || { echo "vcan-vm: cannot resolve linux-image-amd64 (apt-get update?)" >&2; exit 1; }
  (cd "$C" && rm -f ./*.deb && apt-get download "$PKG" >/dev/null 2>&1)
  rm -rf "$C/k"; mkdir "$C/k"
  dpkg-deb --fsys-tarfile "$C"/*.deb | tar -x -C "$C/k" --wildcards './boot/vmlinuz-*' \
    '*/net/can/can.ko' '*/net/can/can-raw.ko' '*/can/dev/can-dev.ko' '*/can/vcan.ko'
  find "$C/k" -name '*.ko' -exec cp {} "$C/" \;
  # vmlinuz is a bzImage with an xz payload; the decompressed ELF vmlinux boots via PVH.
  python3 -c 'import lzma,sys; d=open(sys.argv[1],"rb").read()
open(sys.argv[2],"wb").write(lzma.LZMADecompressor().decompress(d[d.find(b"\xfd7zXZ\0"):]))' \
    "$C"/k/boot/vmlinuz-* "$C/vmlinux.tmp" && mv "$C/vmlinux.tmp" "$C/vmlinux"
  rm -rf "$C/k" "$C"/*.deb
fi
R=$(mktemp -d); trap 'rm -rf "$R"' EXIT
mkdir -p "$R"/root/{bin,mod,proc,sys,dev,tests,tmp}; ROOT=$R/root
cp /bin/busybox "$ROOT/bin/"
for a in sh mount mkdir insmod ip poweroff cut cat seq sleep kill tr; do ln -s busybox "$ROOT/bin/$a"; done
cp "$C"/{can,can-raw,can-dev,vcan}.ko "$ROOT/mod/"
cp "$BIN" "$ROOT/tests/$(basename "$BIN")"
for b in "$BIN" ${VCAN_EXTRA_BINS:-}; do
  [ -x "$b" ] || { echo "vcan-vm: $b is not an executable file" >&2; exit 2; }
  [ "$b" = "$BIN" ] || cp "$b" "$ROOT/bin/$(basename "$b")"
  ldd "$b" 2>/dev/null | grep -oE '/[^ ]+' | while read -r l; do   # dynamic binaries: libs + loader
    mkdir -p "$ROOT${l%/*}"; cp -L "$l" "$ROOT$l"; done || true
done
mkdir -p "$ROOT/work"
for d in ${VCAN_DATA:-}; do cp -r --parents "$d" "$ROOT/work/"; done
printf '%s\n' "$@" > "$ROOT/tests/args"
cat > "$ROOT/init" <<'INIT'
#!/bin/sh
export PATH=/bin HOME=/tmp; cd /work
mount -t proc p /proc; mount -t sysfs s /sys; mount -t devtmpfs d /dev
mkdir -p /dev/shm; mount -t tmpfs -o size=128m shm /dev/shm
ip link set lo up
for m in can can-raw can-dev vcan; do insmod /mod/$m.ko; done
for i in 0 1 2 3; do ip link add dev vcan$i type vcan && ip link set up vcan$i; done
echo "VCAN_UP uptime=$(cut -d' ' -f1 /proc/uptime)"
set --; while IFS= read -r a; do [ -n "$a" ] && set -- "$@" "$a"; done < /tests/args
for t in /tests/*; do [ "$t" = /tests/args ] && continue
  echo "== RUN $t $*"; "$t" "$@"; echo "GUEST_EXIT rc=$?"; done
poweroff -f
INIT
chmod +x "$ROOT/init"
(cd "$ROOT" && find . | busybox cpio -o -H newc 2>/dev/null | gzip -1) > "$R/initrd.gz"
A=${VCAN_ACCEL:-tcg}
[ -z "${VCAN_ACCEL:-}" ] && [ -w /dev/kvm ] && grep -qwE 'vmx|svm' /proc/cpuinfo && A=kvm
X=(); [ "$A" = kvm ] && X=(-cpu host)
timeout "${VCAN_TIMEOUT:-600}" qemu-system-x86_64 -accel "$A" "${X[@]}" -smp 2 -m "${VCAN_MEM:-512}" \
  -nodefaults -no-user-config -display none -serial stdio -no-reboot -kernel "$C/vmlinux" \
  -initrd "$R/initrd.gz" -append "console=ttyS0 panic=-1 quiet" </dev/null | tr -d '\r' \
  | tee "$R/console.log" || true
# QEMU exits 0 on poweroff whatever the test did: decide from the guest's marker.
grep -qx 'GUEST_EXIT rc=0' "$R/console.log"
