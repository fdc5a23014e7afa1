#!/usr/bin/env bash
# The checks CI runs: formatting, the whole test suite on lavapipe, the doc examples and the
# API documentation.
set -euo pipefail
cd "$(dirname "$0")/.."
bash ci/setup.sh
# lavapipe's shaders at 4 lanes, as the command line asks for them (psrestir::gpu::
# prefer_narrow_cpu_simd): half the compilation, the same images.
export LP_NATIVE_VECTOR_WIDTH="${LP_NATIVE_VECTOR_WIDTH:-128}"
if cargo fmt --version >/dev/null 2>&1; then
    cargo fmt --all -- --check
else
    echo "ci/test.sh: rustfmt not installed, format check skipped"
fi
cargo test --all-targets
# Doc examples (not part of --all-targets).
cargo test --doc
# The API documentation builds without warnings (broken or private intra-doc links).
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps --quiet
