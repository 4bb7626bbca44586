#!/usr/bin/env bash
# Firmware CI: checks that `control` stays no_std (builds for the MCU target), builds the STM32
# binary in release and prints its flash and static RAM use against the budgets, failing if over.
#
#   firmware/ci.sh            (from anywhere; installs what is missing, see below)
#
# Installs when missing: the thumbv7em-none-eabihf target (rustup), flip-link (cargo install,
# about 10 s) and an ELF size tool: llvm-size from `rustup component add llvm-tools` (a prebuilt
# download, same on every machine), else an llvm-size or arm-none-eabi-size already on the PATH.
# probe-rs is NOT needed (flashing only) and takes about 20 minutes to build: never install it here.
#
# Budgets (issue 3): flash (text + rodata + data image + vector table) < 64 KiB,
# static RAM (data + bss + uninit) < 24 KiB. Stack and heap are not static: flip-link places the
# stack below the statics, so an overflow faults instead of corrupting them.
set -euo pipefail

FLASH_BUDGET=$((64 * 1024))
RAM_BUDGET=$((24 * 1024))
TARGET=thumbv7em-none-eabihf

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
start=$(date +%s)

step() { printf '\n== %s\n' "$*"; }

step "toolchain"
if ! rustup target list --installed | grep -qx "$TARGET"; then
    rustup target add "$TARGET"
fi
if ! command -v flip-link >/dev/null 2>&1; then
    cargo install flip-link --locked
fi

find_size_tool() {
    local sysroot host
    sysroot="$(rustc --print sysroot)"
    host="$(rustc -vV | sed -n 's/^host: //p')"
    local rustup_llvm_size="$sysroot/lib/rustlib/$host/bin/llvm-size"
    if [ -x "$rustup_llvm_size" ]; then
        echo "$rustup_llvm_size"
    elif command -v llvm-size >/dev/null 2>&1; then
        command -v llvm-size
    elif command -v arm-none-eabi-size >/dev/null 2>&1; then
        command -v arm-none-eabi-size
    fi
}
SIZE="$(find_size_tool)"
if [ -z "$SIZE" ]; then
    rustup component add llvm-tools
    SIZE="$(find_size_tool)"
fi
[ -n "$SIZE" ] || { echo "no ELF size tool found or installable" >&2; exit 1; }
echo "size tool: $SIZE"

step "control builds for $TARGET (no_std check)"
(cd "$root" && cargo check -p control --target "$TARGET" --locked)

step "stm32 firmware, release"
(cd "$here/stm32" && cargo build --release --locked)
# The build honours CARGO_TARGET_DIR when it is set (a shared target directory), so look there.
elf="${CARGO_TARGET_DIR:-$here/stm32/target}/$TARGET/release/passangle-stm32"

step "sizes of $elf"
# SysV format: one line per section, "name size address". Flash holds the vector table, code,
# read-only data and the initial image of .data; static RAM is .data + .bss + .uninit.
"$SIZE" -A "$elf" | awk -v flash_budget="$FLASH_BUDGET" -v ram_budget="$RAM_BUDGET" '
    $1 == ".vector_table" || $1 == ".text" || $1 == ".rodata" { flash += $2 }
    $1 == ".data" { flash += $2; ram += $2 }
    $1 == ".bss" || $1 == ".uninit" { ram += $2 }
    { sizes[$1] = $2 }
    END {
        printf "sections: .vector_table %d, .text %d, .rodata %d, .data %d, .bss %d, .uninit %d bytes\n",
            sizes[".vector_table"], sizes[".text"], sizes[".rodata"], sizes[".data"], sizes[".bss"], sizes[".uninit"]
        printf "flash (vector table + text + rodata + data): %d bytes = %.1f KiB of %d KiB budget (%.0f %%)\n",
            flash, flash / 1024, flash_budget / 1024, 100 * flash / flash_budget
        printf "static RAM (data + bss + uninit):           %d bytes = %.1f KiB of %d KiB budget (%.0f %%)\n",
            ram, ram / 1024, ram_budget / 1024, 100 * ram / ram_budget
        if (flash == 0 || ram == 0) { print "could not read the section sizes" > "/dev/stderr"; exit 1 }
        if (flash > flash_budget) { print "FAIL: flash over budget" > "/dev/stderr"; exit 1 }
        if (ram > ram_budget) { print "FAIL: static RAM over budget" > "/dev/stderr"; exit 1 }
    }'

echo
echo "firmware CI passed in $(( $(date +%s) - start )) s"
