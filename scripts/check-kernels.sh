#!/usr/bin/env bash
# The hot kernels must not call out of line (ARCHITECTURE.md, "Why the kernels
# look the way they do"): an intrinsic wrapped in a closure or an array `map`
# that the compiler did not inline became a call, and the raster's time on
# `million` doubled. This disassembles the release binary and fails when a
# kernel calls try_map, call_mut or a core_arch function, or when a kernel's
# symbol is missing (renamed or inlined away, so the check would see nothing).
#
#   scripts/check-kernels.sh [BINARY]     # default: target/release/rendiff
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
BIN="${1:-${CARGO_TARGET_DIR:-target}/release/rendiff}"
KERNELS=(render_tile_avx2 trace_packet_avx2 trace_packet_avx512 bounds_avx2 bounds_avx512 aim_leaf_avx2 aim_leaf_avx512 fill_grown_avx2 fill_grown_avx512 GeneralTree::query)
command -v objdump >/dev/null || { echo "check-kernels: objdump not found (Debian package binutils)" >&2; exit 2; }
[[ -f "$BIN" ]] || { echo "check-kernels: $BIN: no such binary (cargo build --release first)" >&2; exit 2; }
pattern="$(IFS='|'; echo "${KERNELS[*]}")"
report="$(objdump -dC "$BIN" | awk -v pat="$pattern" '
    /^[0-9a-f]+ </ { f = 0 }
    /^[0-9a-f]+ </ && $0 ~ ("<.*(" pat ")>:$") {
        f = 1; print "KERNEL " $0; next
    }
    f && /call.*(try_map|call_mut|core_arch)/ { print "CALL " $0 }')"
status=0
for k in "${KERNELS[@]}"; do
    if ! grep -q "^KERNEL .*${k}>:" <<<"$report"; then
        echo "check-kernels: $BIN: kernel $k not found" >&2
        status=1
    fi
done
if grep -q "^CALL " <<<"$report"; then
    echo "check-kernels: $BIN: a kernel calls out of line:" >&2
    grep "^CALL " <<<"$report" | cut -c1-200 >&2
    status=1
fi
[[ $status -eq 0 ]] && echo "check-kernels: ${#KERNELS[@]} kernels, no out-of-line calls"
exit $status
