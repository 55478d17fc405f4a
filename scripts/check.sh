#!/usr/bin/env bash
# The main job (README): installs what is missing, builds rendiff, and runs every
# scene on every renderer, writing reports/runs/latest/ (buffers, diff images,
# manifest.json, results.json). Extra arguments go to `rendiff check`.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
scripts/setup.sh
cargo build --release
exec target/release/rendiff check "$@"
