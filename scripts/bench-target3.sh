#!/usr/bin/env bash
# Issue 10, target 3: one text iteration's work outside the UNets, from real CLI runs.
#
# The measurement of docs/benchmarks.md ("Issue 10 at a glance", target 3): icosphere level 5
# (10,242 vertices, 20,480 faces, unit radius), 8 views at 512², the CPU renderer, the tiny IF
# fixture models (fixtures/models/tiny-if), 13 iterations of two Adam steps each, two rayon threads
# (pinned to cores 0 and 1 when `taskset` exists). For each run it prints the medians over
# iterations 2–13 of `metrics.jsonl`'s per-part timings, in ms per iteration; "outside the UNets"
# is `total − guidance_denoiser`, the target's quantity (≤ 80 ms).
#
# Usage: scripts/bench-target3.sh [RUNS [STYLIZE_BINARY]]
#   RUNS            number of runs (default 3); the VM's speed drifts, so compare builds by
#                   alternating their runs, not by one run each
#   STYLIZE_BINARY  a release `stylize` binary to measure (default: builds target/release/stylize)
#                   (the mesh comes from mesh-core's `write_icosphere` example, built either way)
# Needs cargo, python3, and ONNX Runtime (fetched from PyPI by scripts/setup-onnxruntime.sh).
set -euo pipefail

REPO_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
RUNS="${1:-3}"
BIN="${2:-}"

if ! [[ "${RUNS}" =~ ^[1-9][0-9]*$ ]]; then
    echo "error: RUNS must be a positive integer, got '${RUNS}'" >&2
    exit 2
fi
command -v python3 >/dev/null || { echo "error: python3 is needed for the medians" >&2; exit 2; }

cd "${REPO_ROOT}"
if [[ -z "${ORT_DYLIB_PATH:-}" ]]; then
    ORT_DYLIB_PATH="$(bash scripts/setup-onnxruntime.sh | tail -n1)"
fi
export ORT_DYLIB_PATH
if [[ -z "${BIN}" ]]; then
    echo "building the release CLI (all features) ..." >&2
    cargo build --release --locked --bin stylize
    BIN="${REPO_ROOT}/target/release/stylize"
fi
[[ -x "${BIN}" ]] || { echo "error: '${BIN}' is not an executable" >&2; exit 2; }

WORK="$(mktemp -d "${TMPDIR:-/tmp}/bench-target3.XXXXXX")"
trap 'rm -rf "${WORK}"' EXIT

# The 20,480-face icosphere, from mesh-core's own generator.
cargo run --release --locked --quiet -p mesh-core --example write_icosphere -- 5 "${WORK}/ico5.obj"

PIN=()
if command -v taskset >/dev/null && [[ "$(nproc)" -ge 2 ]]; then
    PIN=(taskset -c 0,1)
fi

echo "$(date -u +%FT%TZ)  ${BIN}  load average $(cut -d' ' -f1-3 /proc/loadavg)"
echo "ms per iteration, medians over iterations 2-13:"
for run in $(seq 1 "${RUNS}"); do
    out="${WORK}/run${run}"
    if ! RAYON_NUM_THREADS=2 "${PIN[@]}" "${BIN}" run "${WORK}/ico5.obj" --prompt "a cubist ball" \
        --model fixtures/models/tiny-if -o "${out}" --quiet --set optim.iterations=13 \
        --set run.preview_every=0 >"${out}.log" 2>&1; then
        echo "error: run ${run} failed; its output:" >&2
        tail -n 20 "${out}.log" >&2
        exit 1
    fi
    python3 - "${out}/metrics.jsonl" "${run}" <<'PY'
import json, statistics, sys
rows = [json.loads(line) for line in open(sys.argv[1])]
rows = [r["seconds"] for r in rows if r.get("iteration", 0) >= 2 and "seconds" in r]
if len(rows) != 12:
    sys.exit(f"error: expected 12 timed iterations after the first, found {len(rows)}")
med = lambda f: 1000 * statistics.median(f(s) for s in rows)
print("run %s: render %.1f | guidance outside the UNets %.1f | render backward %.1f | dARAP %.1f"
      " | Adam %.1f || outside the UNets %.1f | UNets %.0f" % (
          sys.argv[2], med(lambda s: s["render"]),
          med(lambda s: s["guidance"] - s["guidance_denoiser"]),
          med(lambda s: s["render_backward"]),
          med(lambda s: s["darap_forward"] + s["darap_backward"]), med(lambda s: s["adam"]),
          med(lambda s: s["total"] - s["guidance_denoiser"]),
          med(lambda s: s["guidance_denoiser"])))
PY
done
