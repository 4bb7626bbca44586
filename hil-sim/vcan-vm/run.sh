#!/usr/bin/env bash
# Runs a shell command inside a throw-away Linux guest that has real SocketCAN (vcan0 up), and
# returns its output and exit code. The guest sees the host's / read-only (with a writable tmpfs
# overlay) and starts in the caller's working directory, so host-built binaries run unchanged.
#
#   hil-sim/vcan-vm/run.sh 'candump -n 1 vcan0 & cansend vcan0 123#01; wait'
#
# Environment: VCAN_VM_CACHE (default <repo>/target/vcan-vm), VCAN_VM_ACCEL (kvm|tcg, default:
# kvm only where kvm_intel/kvm_amd is loaded; a paravirtual /dev/kvm cannot boot a stock kernel),
# VCAN_VM_MEM (default 1024 MB), VCAN_VM_TIMEOUT (seconds, default 1800).
# VCAN_VM_OUT: a host folder that receives what the guest command leaves in $VCAN_VM_OUT_GUEST.
# In the guest: VCAN_VM_GUEST=1, CAN_UTILS=<dir with candump/cansend>, PATH extended with it,
# VCAN_VM_OUT_GUEST=<a writable folder whose files are copied back to $VCAN_VM_OUT on the host>.
# Exit codes: the command's own; 77 = SKIPPED (qemu cannot run here at all, with the reason);
# 124 = timeout; 125 = the guest failed before running the command.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
cache="${VCAN_VM_CACHE:-$repo/target/vcan-vm}"
export VCAN_VM_CACHE="$cache"
[[ $# -ge 1 ]] || { echo "usage: $0 'shell command'" >&2; exit 2; }

if ! "$here/setup.sh"; then
  echo "vcan-vm: SKIPPED: could not prepare qemu and the guest kernel (see the setup messages above)" >&2
  exit 77
fi
qemu="$cache/qemu/usr/bin/qemu-system-x86_64"
export LD_LIBRARY_PATH="$cache/qemu/usr/lib/x86_64-linux-gnu:$cache/qemu/lib/x86_64-linux-gnu${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
export QEMU_MODULE_DIR="$cache/qemu/usr/lib/x86_64-linux-gnu/qemu"
if ! "$qemu" --version >/dev/null 2>&1; then
  echo "vcan-vm: SKIPPED: qemu does not start here: $("$qemu" --version 2>&1 | head -n2)" >&2
  exit 77
fi

accel="${VCAN_VM_ACCEL:-}"
if [[ -z "$accel" ]]; then
  if [[ -w /dev/kvm ]] && { [[ -d /sys/module/kvm_intel ]] || [[ -d /sys/module/kvm_amd ]]; }; then
    accel=kvm
  else
    accel=tcg
  fi
fi
case "$accel" in
  kvm) accel_args=(-accel kvm -cpu host); why="KVM (hardware virtualisation)";;
  tcg) accel_args=(-accel tcg -cpu max); why="TCG (pure emulation, slower: no usable /dev/kvm with kvm_intel/kvm_amd)";;
  *) echo "vcan-vm: VCAN_VM_ACCEL must be kvm or tcg, not '$accel'" >&2; exit 2;;
esac
echo "vcan-vm: booting the guest with $why" >&2

xchg="$(mktemp -d "$cache/xchg.XXXXXX")"
mkdir -p "$xchg/out"
trap 'rm -rf "$xchg"' EXIT
printf '%s\n' "$*" >"$xchg/cmd"
pwd >"$xchg/cwd"
{
  printf 'export PATH=%q\n' "$cache/canutils/usr/bin:$PATH"
  printf 'export CAN_UTILS=%q\n' "$cache/canutils/usr/bin"
  printf 'export VCAN_VM_OUT_GUEST=/mnt/xchg/out\n'
  for v in RUST_BACKTRACE RUST_LOG CARGO_TARGET_DIR SIL_CAN_IFACE; do
    [[ -n "${!v:-}" ]] && printf 'export %s=%q\n' "$v" "${!v}"
  done
} >"$xchg/env"

start=$(date +%s.%N)
set +e
timeout "${VCAN_VM_TIMEOUT:-1800}" "$qemu" -M pc "${accel_args[@]}" -smp 1 -m "${VCAN_VM_MEM:-1024}" \
  -kernel "$cache/kernel/vmlinux" -initrd "$cache/initramfs.cpio.gz" \
  -append "console=ttyS0 quiet loglevel=1 panic=-1 mitigations=off cryptomgr.notests acpi=noirq norandmaps" \
  -display none -monitor none -no-reboot \
  -chardev stdio,id=con,signal=off -serial chardev:con \
  -virtfs local,path=/,mount_tag=hostroot,security_model=none,readonly=on,multidevs=remap \
  -virtfs "local,path=$xchg,mount_tag=xchg,security_model=none" \
  </dev/null | tr -d '\r'
status=${PIPESTATUS[0]}
set -e
end=$(date +%s.%N)
elapsed=$(awk -v a="$start" -v b="$end" 'BEGIN{printf "%.1f", b-a}')
if [[ $status -eq 124 ]]; then
  echo "vcan-vm: TIMEOUT after ${VCAN_VM_TIMEOUT:-1800} s ($accel)" >&2; exit 124
fi
if [[ ! -f "$xchg/rc" ]]; then
  echo "vcan-vm: the guest ended without an exit code (qemu status $status, $accel, ${elapsed} s)" >&2; exit 125
fi
rc="$(cat "$xchg/rc")"
if [[ -n "${VCAN_VM_OUT:-}" ]]; then
  mkdir -p "$VCAN_VM_OUT" && cp -r "$xchg/out/." "$VCAN_VM_OUT/"
fi
echo "vcan-vm: guest command exited $rc ($accel, ${elapsed} s wall including boot)" >&2
exit "$rc"
