#!/usr/bin/env bash
# The firmware on an emulated STM32F407: builds the release ELF and the link codec, installs the
# Python dependencies into a venv, runs every scenario (firmware/emu/scenarios.py) and exits
# non-zero if one fails. What the emulated board models: firmware/README.md.
#
#   firmware/emu/run.sh                      all scenarios
#   firmware/emu/run.sh --only drive panic   some of them
#
# Environment: EMU_VENV (default target/emu-venv) for the Python venv; CARGO_TARGET_DIR is
# honoured like firmware/ci.sh does. Decoded defmt logs go to target/emu-logs/SCENARIO.log.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
start=$(date +%s)
TARGET=thumbv7em-none-eabihf

venv="${EMU_VENV:-$root/target/emu-venv}"
if ! "$venv/bin/python" -c 'import unicorn, elftools' 2>/dev/null; then
    echo "== python venv $venv (unicorn, pyelftools)"
    if ! python3 -c 'import venv, ensurepip' 2>/dev/null; then
        # Debian ships venv's pip bootstrap separately.
        if [[ $(id -u) == 0 ]] && command -v apt-get >/dev/null; then
            (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3-venv) >/dev/null
        else
            echo "error: python3 venv is missing: apt-get install python3-venv" >&2
            exit 1
        fi
    fi
    python3 -m venv "$venv"
    "$venv/bin/pip" install --quiet 'unicorn==2.1.4' 'pyelftools==0.33'
fi

if ! rustup target list --installed | grep -qx "$TARGET"; then
    rustup target add "$TARGET"
fi
command -v flip-link >/dev/null 2>&1 || cargo install flip-link --locked

echo "== build: firmware (release) and the link codec"
(cd "$here/../stm32" && cargo build --release --locked)
(cd "$root" && cargo build -p control --example emu_link --locked)
elf="${CARGO_TARGET_DIR:-$here/../stm32/target}/$TARGET/release/passangle-stm32"
link="${CARGO_TARGET_DIR:-$root/target}/debug/examples/emu_link"

echo "== scenarios"
"$venv/bin/python" "$here/scenarios.py" --elf "$elf" --link "$link" \
    --log "${CARGO_TARGET_DIR:-$root/target}/emu-logs" "$@"
echo "emulated-board tests passed in $(( $(date +%s) - start )) s"
