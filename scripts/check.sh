#!/usr/bin/env bash
# The main job (README): installs what is missing, builds rendiff, and runs every
# scene on every renderer (the built-in ones, and rendiff-wgpu declared in
# renderers/wgpu.toml), writing reports/runs/latest/ (buffers, diff images,
# manifest.json, results.json). Extra arguments go to `rendiff check`.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
scripts/setup.sh
cargo build --release --workspace
# The wgpu renderer joins through the same door as a user's own renderer
# (renderers/wgpu.toml, docs/your-renderer.md); its binary is found on PATH.
export PATH="$PWD/target/release:$PATH"
exec target/release/rendiff check --renderers renderers/wgpu.toml "$@"
