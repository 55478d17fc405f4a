#!/usr/bin/env bash
# The test command (README): installs what is missing, then runs every test.
#   1. scripts/setup.sh  (apt packages + .venv, quick when already done)
#   2. the Python harness's own tests (backend conversions, comparison)
#   3. cargo test: unit tests, raster==trace, watertightness, bad input, and the
#      cross-renderer conformance suite (one test per scene x backend x buffer), and
#      the metamorphic relations on every backend (docs/metamorphic.md).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
scripts/setup.sh
# Tests that drive the release binaries (the harness's end-to-end tests, rendiff-wgpu
# against the core, the conformance run, which runs rendiff-wgpu like the main job)
# find them in target/release; built first so that none skips.
echo "==> cargo build --release -p rendiff -p rendiff-wgpu"
cargo build --release -p rendiff -p rendiff-wgpu
echo "==> Python harness tests"
(cd harness && ../.venv/bin/python -m pytest -q tests)
echo "==> cargo test"
cargo test --workspace --all-targets "$@"
