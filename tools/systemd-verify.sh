#!/usr/bin/env bash
# Checks the systemd units in systemd/: `systemd-analyze verify` on every unit, plus
# the stack's own policy (Type=notify only where the binary sends sd_notify, every daemon
# Type=notify with a watchdog, never restarted, real-time limits set, the isolation keys). Exits non-zero on ANY warning or error: systemd-analyze
# itself exits 0 on e.g. unknown keys or unparsable values ("ignoring"), so its output must be
# empty to pass.
#
# The units start /usr/local/bin/<binary>, and verify checks that the executable exists. Rather
# than touching the host, the units are verified inside a throw-away root (--root): the units in
# its /etc/systemd/system, the host's own system units (sysinit.target & co.) in its
# /usr/lib/systemd/system, and an executable stub for every Exec*= path. A canary (a copy with
# an unknown key) must be reported, so a verify that silently checks nothing fails too.
# Usage: tools/systemd-verify.sh   (needs systemd-analyze; installed with apt-get when missing)
set -euo pipefail
cd "$(dirname "$0")/.."

if ! command -v systemd-analyze >/dev/null; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "systemd-analyze missing: installing systemd (apt-get)"
    apt-get install -y --no-install-recommends systemd >/dev/null ||
      { apt-get update >/dev/null && apt-get install -y --no-install-recommends systemd >/dev/null; }
  else
    echo "systemd-analyze not found: install the systemd package" >&2
    exit 1
  fi
fi

units=(systemd/*.service systemd/*.target)
[ -e "${units[0]}" ] || { echo "no units in systemd/" >&2; exit 1; }

root=$(mktemp -d)
trap 'rm -rf "$root"' EXIT
mkdir -p "$root/etc/systemd/system" "$root/usr/lib/systemd"
sysunits=""
for d in /usr/lib/systemd/system /lib/systemd/system; do
  if [ -f "$d/sysinit.target" ]; then sysunits=$d; break; fi
done
[ -n "$sysunits" ] || { echo "no system unit directory with sysinit.target found" >&2; exit 1; }
cp -a "$sysunits" "$root/usr/lib/systemd/system"
cp "${units[@]}" "$root/etc/systemd/system/"

# Executable stubs for every Exec*= command (prefixes -@:+! stripped; paths must be absolute).
fail=0
while IFS= read -r line; do
  cmd=${line#*=}
  cmd=${cmd#"${cmd%%[!-@:+!]*}"}
  exe=${cmd%% *}
  case "$exe" in
    /*) mkdir -p "$root$(dirname "$exe")"
        printf '#!/bin/sh\nexit 0\n' >"$root$exe"
        chmod 0755 "$root$exe" ;;
    *) echo "${line}: Exec path is not absolute" >&2; fail=1 ;;
  esac
done < <(grep -h '^Exec[A-Za-z]*=' "${units[@]}")

verify() { # verify ROOT UNIT-NAMES... -> prints systemd-analyze's output, returns its status
  local r=$1
  shift
  (cd "$r/etc/systemd/system" && systemd-analyze verify --root="$r" "$@" 2>&1)
}

names=()
for u in "${units[@]}"; do names+=("$(basename "$u")"); done
set +e
out=$(verify "$root" "${names[@]}")
rc=$?
set -e
if [ $rc -ne 0 ] || [ -n "$out" ]; then
  echo "systemd-analyze verify (exit $rc):"
  echo "$out"
  fail=1
else
  echo "systemd-analyze verify: ${#names[@]} units clean (${names[*]})"
fi

# Canary: the same verify must report an unknown key.
canary=$root/etc/systemd/system/crs-verify-canary.service
{ sed -n '1,/^\[Service\]/p' "${units[0]}"; echo "NoSuchKey=1"; sed -n '/^\[Service\]/,$p' "${units[0]}" | tail -n +2; } >"$canary"
set +e
cout=$(verify "$root" crs-verify-canary.service)
set -e
if ! grep -q "NoSuchKey" <<<"$cout"; then
  echo "canary: systemd-analyze verify did not report an unknown key: the check is not working" >&2
  fail=1
fi
rm -f "$canary"

# Project policy on top of systemd's syntax check.
policy() { echo "policy: $*" >&2; fail=1; }
crate_of() { # unit file -> crate directory of its binary
  local exe
  exe=$(grep -h '^ExecStart=' "$1" | head -1 | sed 's/^ExecStart=[-@:+!]*//; s/ .*//')
  echo "crates/$(basename "$exe")"
}
for u in systemd/*.service; do
  n=$(basename "$u")
  if [ "$n" = crs-isolation.service ]; then
    # Root's oneshot set-up of the namespaces: no daemon, no real time.
    grep -q '^Type=oneshot$' "$u" || policy "$n: must be Type=oneshot"
    grep -q '^RemainAfterExit=yes$' "$u" || policy "$n: RemainAfterExit=yes missing"
    grep -q '^ExecStop=' "$u" || policy "$n: ExecStop= missing (the namespace must go on stop)"
    grep -q '^PartOf=crs-stack.target$' "$u" || policy "$n: PartOf=crs-stack.target missing"
    grep -q '^NS=crs$' systemd/crs-isolation && grep -q 'ip netns add' systemd/crs-isolation ||
      policy "crs-isolation: does not create the network namespace crs"
    continue
  fi
  crate=$(crate_of "$u")
  sends_ready=no; sends_watchdog=no
  if [ -d "$crate/src" ]; then
    # Directly, or through crs-service (notify_ready / Watchdog::spawn).
    grep -rqE 'READY=1|crs_service::notify_ready' "$crate/src" && sends_ready=yes
    grep -rqE 'WATCHDOG=1|crs_service::Watchdog::spawn' "$crate/src" && sends_watchdog=yes
  fi
  type=$(sed -n 's/^Type=//p' "$u" | tail -1)
  if [ "$type" = notify ] && [ $sends_ready = no ]; then
    policy "$n: Type=notify but $crate never sends READY=1 (start would time out)"
  fi
  if [ "$type" != notify ] && [ $sends_ready = yes ]; then
    echo "note: $n: $crate sends READY=1: switch the unit to Type=notify"
  fi
  if grep -q '^WatchdogSec=' "$u" && [ $sends_watchdog = no ]; then
    policy "$n: WatchdogSec= set but $crate never sends WATCHDOG=1 (systemd would kill it)"
  fi
  grep -q '^LimitMEMLOCK=infinity$' "$u" || policy "$n: LimitMEMLOCK=infinity missing"
  grep -q '^CPUSchedulingPolicy=fifo$' "$u" || policy "$n: CPUSchedulingPolicy=fifo missing"
  grep -q '^CPUSchedulingPriority=' "$u" || policy "$n: CPUSchedulingPriority missing"
  grep -q '^CPUAffinity=' "$u" || policy "$n: CPUAffinity missing"
  grep -q '^PartOf=crs-stack.target$' "$u" || policy "$n: PartOf=crs-stack.target missing"
  # Every daemon tells systemd when it is ready and is watched (sd_notify via crs-service).
  [ "$type" = notify ] || policy "$n: must be Type=notify (every daemon sends READY=1)"
  grep -q '^WatchdogSec=' "$u" || policy "$n: WatchdogSec= missing"
  grep -q '^Restart=no$' "$u" || policy "$n: must never restart (Restart=no)"
  # Isolation: the CAN interfaces in the stack's network namespace, iceoryx2's /tmp and
  # /dev/shm the stack's own, the namespaces set up first.
  grep -q '^NetworkNamespacePath=/run/netns/crs$' "$u" || policy "$n: NetworkNamespacePath=/run/netns/crs missing"
  grep -Eq '^BindPaths=.*:/tmp( |$)' "$u" || policy "$n: BindPaths= of the stack's /tmp missing"
  grep -Eq '^BindPaths=.*:/dev/shm( |$)' "$u" || policy "$n: BindPaths= of the stack's /dev/shm missing"
  grep -q '^PrivateTmp=yes' "$u" && policy "$n: PrivateTmp=yes would split the stack's /tmp per unit"
  grep -Eq '^Requires=.*\bcrs-isolation.service\b' "$u" || policy "$n: Requires=crs-isolation.service missing"
  grep -Eq '^After=.*\bcrs-isolation.service\b' "$u" || policy "$n: After=crs-isolation.service missing"
  grep -q '^User=crs$' "$u" || policy "$n: must run as user crs (iceoryx2 connects one user's processes)"
done
mc=systemd/crs-motion-core.service
grep -q '^Type=notify$' "$mc" || policy "$mc: must be Type=notify"
grep -q '^WatchdogSec=' "$mc" || policy "$mc: WatchdogSec missing"
grep -q '^Restart=no$' "$mc" || policy "$mc: must never restart (Restart=no)"
for dep in crs-safety-monitor.service crs-drive-io.service; do
  grep -Eq "^BindsTo=.*\b$dep\b" "$mc" || policy "$mc: BindsTo=$dep missing"
  grep -Eq "^After=.*\b$dep\b" "$mc" || policy "$mc: After=$dep missing"
done
# The target: Requires= the monitor and drive-io, Wants= motion-core, never Requires= it (a
# stop job of motion-core, e.g. its BindsTo= after the monitor died, would stop the target and
# through PartOf= drive-io, which must stay up holding the drives stopped: systemd/README.md).
t=systemd/crs-stack.target
for dep in crs-safety-monitor.service crs-drive-io.service; do
  grep -Eq "^Requires=.*\b$dep\b" "$t" || policy "$t: Requires=$dep missing"
done
grep -Eq '^Wants=.*\bcrs-motion-core.service\b' "$t" || policy "$t: Wants=crs-motion-core.service missing"
grep -Eq '^(Requires|BindsTo|Requisite)=.*\bcrs-motion-core.service\b' "$t" &&
  policy "$t: must not Require= crs-motion-core.service (its stop would stop drive-io through the target)"

if [ $fail -ne 0 ]; then
  echo "systemd-verify: FAILED" >&2
  exit 1
fi
echo "systemd-verify: ok"
