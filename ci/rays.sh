#!/usr/bin/env bash
# Ray throughput of the two tracers, alternating runs of the same render:
#   bash ci/rays.sh [ROUNDS] [BINARY...]
# Each round renders the bundled scene (camera `main`, 256x256, 16 spp) once per binary
# (default: target/release/psrestir) and per tracer (PSRESTIR_TRACER=software, then
# ray-query where the adapter offers ray queries), and prints the rays/s line of each run.
# Give an older build as a second binary to compare builds in the same run.
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=${1:-3}
shift || true
bins=("$@")
if [ ${#bins[@]} -eq 0 ]; then
    cargo build --release --quiet
    bins=(target/release/psrestir)
fi
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
"${bins[0]}" adapter 2>/dev/null | head -1
for r in $(seq "$rounds"); do
    for bin in "${bins[@]}"; do
        for tracer in software ray-query; do
            if ! line=$(PSRESTIR_TRACER=$tracer "$bin" render scenes/default/scene.gltf \
                --camera main --spp 16 --size 256x256 -o "$out/r.exr" 2>&1 | tail -1); then
                line="not available: $line"
            fi
            echo "round $r  $bin  $tracer: ${line#wrote }"
        done
    done
done
