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
# Every test target compiled once, then run one by one with its time, so that growth is
# seen (the slowest last). The same tests as `cargo test --all-targets`.
cargo test --all-targets --no-run
times=()
timed() {
    local label="$1" t0 t1
    shift
    t0=$(date +%s)
    "$@"
    t1=$(date +%s)
    times+=("$((t1 - t0)) s  $label")
}
timed "unit tests (src/)" cargo test --lib --bins --examples
for f in tests/*.rs; do
    name="$(basename "$f" .rs)"
    timed "tests/$name.rs" cargo test --test "$name"
done
# Doc examples (not part of --all-targets).
timed "doc examples" cargo test --doc
# The API documentation builds without warnings (broken or private intra-doc links).
RUSTDOCFLAGS="-D warnings" timed "API documentation" cargo doc --no-deps --quiet
# The Python package (pyproject.toml, python/) and its tests. CI builds it with the dev profile,
# which reuses every dependency the Rust tests just compiled: the root Cargo.toml's
# dev-dependencies and python/Cargo.toml give both builds the same features, so only psrestir
# (without its test hooks), pyo3 and the bindings compile again (35 s from a clean clone on 2
# cores, against 259 s when every crate downstream of a procedural macro compiled twice).
# A release build, `pip install .`, is what users run; the tests check behaviour, not speed.
# pytest exits non-zero when it collects no test.
PYTHON="${PYTHON:-python3}"
"$PYTHON" -m pip install --quiet --disable-pip-version-check "maturin>=1.9,<2" numpy pytest
MATURIN_PEP517_ARGS="--profile dev" timed "Python package build" "$PYTHON" -m pip install \
    --quiet --disable-pip-version-check --no-build-isolation --force-reinstall --no-deps .
timed "tests/python (pytest)" "$PYTHON" -m pytest -q tests/python
echo "ci/test.sh: time per test file and step:"
printf '  %s\n' "${times[@]}" | sort -n -k1
