#!/usr/bin/env bash
# Prepares everything the vcan guest needs, under a cache folder (default: <repo>/target/vcan-vm):
#   debs/      the downloaded Debian packages (kept, so a warm run downloads nothing)
#   qemu/      qemu-system-x86 and its libraries, unpacked with `dpkg -x` (never installed system-wide:
#              `apt-get install qemu-system-x86` wants to remove packages on this image)
#   kernel/    the Debian generic kernel, its uncompressed vmlinux, and its modules
#   canutils/  can-utils (candump, cansend) from Debian, run inside the guest
#   initramfs.cpio.gz  busybox-static + the CAN/9p/virtio modules + init (hil-sim/vcan-vm/init)
# Idempotent: each step is skipped when its output exists. Prints what it does; exits non-zero with
# a message naming the step that failed. See the README section "Firmware in the loop".
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
cache="${VCAN_VM_CACHE:-$repo/target/vcan-vm}"
mkdir -p "$cache/debs"
log() { echo "vcan-vm setup: $*" >&2; }
die() { echo "vcan-vm setup: FAILED: $*" >&2; exit 1; }

# Guest modules, in load order (file names use dashes or underscores; modprobe resolves both).
MODULES="virtio_pci virtio_console 9pnet_virtio 9p overlay can can_raw vcan"

need_lists() {
  if ! apt-cache show linux-image-amd64 >/dev/null 2>&1; then
    log "apt lists are empty: running apt-get update"
    apt-get update -qq || die "apt-get update"
  fi
}

download() { # download PKG... into debs/ (skips those already there)
  local missing=()
  local p
  for p in "$@"; do
    compgen -G "$cache/debs/${p}_*.deb" >/dev/null || missing+=("$p")
  done
  if ((${#missing[@]})); then
    log "downloading ${missing[*]}"
    (cd "$cache/debs" && apt-get download -q -o APT::Sandbox::User=root "${missing[@]}" >/dev/null) || die "apt-get download ${missing[*]}"
  fi
}

unpack() { # unpack DEST PKG...
  local dest="$1"; shift
  mkdir -p "$dest"
  local p
  for p in "$@"; do
    local deb
    deb="$(compgen -G "$cache/debs/${p}_*.deb" | head -n1)" || die "no .deb for $p"
    dpkg -x "$deb" "$dest" || die "dpkg -x $deb"
  done
}

# 1. Kernel: resolve the ABI package through the linux-image-amd64 metapackage.
if [[ ! -f "$cache/kernel/vmlinux" ]]; then
  need_lists
  kpkg="$(apt-cache depends linux-image-amd64 | awk '/Depends: linux-image-[0-9]/ {print $2; exit}')"
  [[ -n "$kpkg" ]] || die "cannot resolve the kernel package behind linux-image-amd64"
  download "$kpkg"
  rm -rf "$cache/kernel.tmp" && unpack "$cache/kernel.tmp" "$kpkg"
  vmlinuz="$(compgen -G "$cache/kernel.tmp/boot/vmlinuz-*" | head -n1)" || die "no vmlinuz in $kpkg"
  # Uncompressed vmlinux boots about 6 s faster under TCG. The bzImage holds an xz stream: find its
  # magic and decompress from there (xz ignores trailing garbage with --single-stream).
  off="$(LC_ALL=C grep -abo $'\xfd7zXZ' "$vmlinuz" | head -n1 | cut -d: -f1)" || true
  if [[ -n "$off" ]]; then
    # tail ends with SIGPIPE when xz stops at the end of the stream: not an error here.
    (set +o pipefail; tail -c +"$((off + 1))" "$vmlinuz" | xz -dc --single-stream >"$cache/kernel.tmp/vmlinux" 2>/dev/null) || true
  fi
  if [[ -s "$cache/kernel.tmp/vmlinux" && "$(head -c 4 "$cache/kernel.tmp/vmlinux" | od -An -tx1 | tr -d ' \n')" == 7f454c46 ]]; then
    log "extracted the uncompressed vmlinux (boots faster under TCG)"
  else
    log "could not extract vmlinux; booting the compressed vmlinuz (slower)"
    cp "$vmlinuz" "$cache/kernel.tmp/vmlinux"
  fi
  rm -rf "$cache/kernel" && mv "$cache/kernel.tmp" "$cache/kernel"
fi
kver="$(basename "$(compgen -G "$cache/kernel/lib/modules/*" | head -n1)")"
[[ -n "$kver" ]] || die "no modules in $cache/kernel"

# 2. busybox-static, can-utils.
if [[ ! -x "$cache/busybox/bin/busybox" ]]; then
  need_lists
  download busybox-static
  rm -rf "$cache/busybox" && unpack "$cache/busybox" busybox-static
fi
if [[ ! -x "$cache/canutils/usr/bin/candump" ]]; then
  need_lists
  download can-utils
  rm -rf "$cache/canutils" && unpack "$cache/canutils" can-utils
fi

# 3. qemu: the packages `apt-get install -s qemu-system-x86` would install, unpacked privately.
if [[ ! -x "$cache/qemu/usr/bin/qemu-system-x86_64" ]]; then
  need_lists
  mapfile -t pkgs < <(apt-get install -s -qq --no-install-recommends qemu-system-x86 2>/dev/null | awk '/^Inst /{print $2}')
  ((${#pkgs[@]})) || pkgs=(qemu-system-x86)
  download "${pkgs[@]}"
  rm -rf "$cache/qemu" && unpack "$cache/qemu" "${pkgs[@]}"
fi

# 4. initramfs: busybox, the modules and their dependencies, modules.dep, init.
initrd="$cache/initramfs.cpio.gz"
if [[ ! -f "$initrd" || "$here/init" -nt "$initrd" || "$0" -nt "$initrd" ]]; then
  log "building the initramfs (kernel $kver)"
  root="$cache/initramfs.tmp"
  rm -rf "$root" && mkdir -p "$root"/{bin,sbin,proc,sys,dev,tmp,mnt/lower,mnt/rw,mnt/xchg,newroot,lib/modules/"$kver"}
  cp "$cache/busybox/bin/busybox" "$root/bin/busybox"
  moddir="$cache/kernel/lib/modules/$kver"
  cp "$moddir"/modules.order "$moddir"/modules.builtin* "$root/lib/modules/$kver/" 2>/dev/null || true
  "$cache/busybox/bin/busybox" depmod -b "$cache/kernel" "$kver" 2>/dev/null || die "busybox depmod"
  # Copy each wanted module and everything modules.dep says it needs.
  declare -A copied=()
  add_module() {
    local name="$1" rel
    rel="$(awk -F: -v n1="/${name}.ko" -v n2="/${name//_/-}.ko" '
      { f=$1; sub(/\.xz$|\.gz$|\.zst$/, "", f) }
      (substr(f, length(f)-length(n1)+1) == n1 || substr(f, length(f)-length(n2)+1) == n2) {print $0; exit}' "$moddir/modules.dep")"
    [[ -n "$rel" ]] || { log "module $name is built in or absent (ok if built in)"; return 0; }
    local file="${rel%%:*}" deps="${rel#*:}"
    [[ -n "${copied[$file]:-}" ]] && return 0
    copied[$file]=1
    mkdir -p "$root/lib/modules/$kver/$(dirname "$file")"
    cp "$moddir/$file" "$root/lib/modules/$kver/$file"
    local d
    for d in $deps; do
      local base; base="$(basename "$d")"; base="${base%%.ko*}"
      add_module "$base"
    done
  }
  for m in $MODULES; do add_module "$m"; done
  # Compressed modules: busybox modprobe reads plain .ko only; decompress xz ones.
  find "$root/lib/modules" -name '*.ko.xz' -exec xz -d {} +
  "$cache/busybox/bin/busybox" depmod -b "$root" "$kver" || die "depmod in initramfs"
  cp "$here/init" "$root/init" && chmod +x "$root/init"
  (cd "$root" && find . | "$cache/busybox/bin/busybox" cpio -o -H newc 2>/dev/null | gzip -1 >"$initrd.tmp") || die "cpio"
  mv "$initrd.tmp" "$initrd"
  rm -rf "$root"
fi
echo "$kver" >"$cache/kernel-version"
log "ready in $cache (kernel $kver)"
