#!/usr/bin/env bash
# The GPU check of the text path (docs/models.md, "The GPU check"), for a Linux machine with an
# NVIDIA GPU and no network. Two halves:
#
#   scripts/gpu_check.sh pack BUNDLE [--provider-wheel WHL]   # on a build machine (cargo, network)
#   scripts/gpu_check.sh run BUNDLE [--work DIR] [--only STEP] [--device cuda:N]   # on the GPU machine
#   scripts/gpu_check.sh split FILE OUTDIR [PART_SIZE]        # FILE -> OUTDIR/FILE.xz.part-* + SHA256SUMS
#   scripts/gpu_check.sh reassemble PARTS_DIR NAME DEST_DIR   # parts -> DEST_DIR/NAME, sha256-verified
#
# `pack` builds what `run` needs into BUNDLE: bin/stylize (release, stripped, features text + cuda),
# bin/unet_bench (the diffusion-onnx example, cuda), bin/raster_gpu_tests (raster-diff's wgpu parity
# tests), the tiny model fixtures and a mesh, and ort/: libonnxruntime.so.1.31.1 and
# libonnxruntime_providers_shared.so whole, libonnxruntime_providers_cuda.so (284 MB) as xz-compressed
# parts of 60 MB (`split`), with SHA256SUMS of the whole files.
#
# `run` steps, in order of value, each printing its figure and leaving WORK/done/STEP when it passed
# (a rerun skips passed steps, so the machine may go away between calls; --only STEP reruns one):
#   setup      reassemble and verify the CUDA provider; LD_LIBRARY_PATH from the nvidia-* wheels;
#              `stylize doctor` (must find the CUDA provider loading and a GPU)
#   agree      tiny IF (fp32 with TF32 off, and fp16) stage I and II on CUDA vs the CPU provider:
#              max |difference| within 1e-4 + 1e-4·max|y| (fp32) / 1e-2 + 1e-2·max|y| (fp16)
#   throughput one real-size random-weight stage-II call (scripts/realsize_check.py's 1.24 B-parameter
#              UNet, fp16, batch 16 at 256 px) timed with and without IO binding, and the same UNet at
#              64 px (stage I's resolution): ms per call and TFLOP/s (12.18 / 0.77 TFLOP per sample,
#              PyTorch's FLOP counter on that UNet). Needs torch, diffusers, onnx in python3 (or
#              wheels in BUNDLE/wheels), ~6 GB of disk.
#   run        `stylize run --prompt` with the tiny models on the GPU, 4 iterations: wall time
#   wgpu       the wgpu renderer's parity tests on the real GPU (Vulkan); fails if they SKIP
#
# Without a GPU (or with --device cpu) `run` still does what it can on the CPU provider and says
# which steps it could not do; argument errors exit 2.
set -euo pipefail

PART_SIZE_DEFAULT=60M
ORT_VERSION=1.31.1
PROVIDER=libonnxruntime_providers_cuda.so
STEPS=(setup agree throughput run wgpu)

die() { echo "gpu_check: error: $*" >&2; exit 1; }
bad_arg() { echo "gpu_check: $*" >&2; exit 2; }
usage() { sed -n '2,9p' "$0" >&2; exit 2; }
sha_of() { sha256sum "$1" | cut -d' ' -f1; }
say() { echo "== $*"; }

# split FILE OUTDIR [SIZE]: xz -9 then split; SHA256SUMS holds the whole file's sha256 (appended).
cmd_split() {
    [[ $# -ge 2 && $# -le 3 ]] || usage
    local file=$1 out=$2 size=${3:-$PART_SIZE_DEFAULT} name
    [[ -f $file ]] || die "no such file: $file"
    name=$(basename "$file")
    mkdir -p "$out"
    rm -f "$out/$name.xz.part-"*
    xz -9 -T0 -c "$file" | split -b "$size" -d -a 3 - "$out/$name.xz.part-"
    touch "$out/SHA256SUMS"
    grep -v "  $name\$" "$out/SHA256SUMS" > "$out/SHA256SUMS.new" || true
    echo "$(sha_of "$file")  $name" >> "$out/SHA256SUMS.new"
    mv "$out/SHA256SUMS.new" "$out/SHA256SUMS"
    echo "$out: $(ls "$out/$name.xz.part-"* | wc -l) part(s) of $name"
}

# reassemble PARTS_DIR NAME DEST_DIR: idempotent (a DEST with the right sha256 is kept).
cmd_reassemble() {
    [[ $# -eq 3 ]] || usage
    local parts=$1 name=$2 dest=$3 want got tmp
    [[ -f $parts/SHA256SUMS ]] || die "$parts/SHA256SUMS is missing (made by \`gpu_check.sh split\`)"
    want=$(awk -v n="$name" '$2 == n { print $1 }' "$parts/SHA256SUMS")
    [[ -n $want ]] || die "$parts/SHA256SUMS has no entry for $name"
    mkdir -p "$dest"
    if [[ -f $dest/$name && $(sha_of "$dest/$name") == "$want" ]]; then
        echo "$dest/$name: present, sha256 ok"
        return 0
    fi
    shopt -s nullglob
    local files=("$parts/$name.xz.part-"*)
    shopt -u nullglob
    [[ ${#files[@]} -gt 0 ]] || die "no parts $parts/$name.xz.part-* (copy all of them)"
    tmp="$dest/.$name.partial"
    if ! cat "${files[@]}" | xz -d -c > "$tmp" 2>/dev/null; then
        rm -f "$tmp"
        die "the parts of $name do not decompress: a part is missing or damaged (${#files[@]} found)"
    fi
    got=$(sha_of "$tmp")
    if [[ $got != "$want" ]]; then
        rm -f "$tmp"
        die "$name reassembled from ${#files[@]} part(s) has sha256 $got, expected $want: a part is missing, damaged or from another file"
    fi
    mv "$tmp" "$dest/$name"
    echo "$dest/$name: reassembled from ${#files[@]} part(s), sha256 ok"
}

cmd_pack() {
    [[ $# -ge 1 ]] || usage
    local bundle=$1 wheel=""
    shift
    while [[ $# -gt 0 ]]; do
        case $1 in
            --provider-wheel) wheel=${2:?--provider-wheel needs a file}; shift 2 ;;
            *) usage ;;
        esac
    done
    local repo
    repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
    mkdir -p "$bundle/bin" "$bundle/ort" "$bundle/fixtures"
    (cd "$repo" && cargo build --release --locked -p stylize-cli --features cuda --bin stylize)
    (cd "$repo" && cargo build --release --locked -p diffusion-onnx --features cuda --example unet_bench)
    local test_bin
    test_bin=$(cd "$repo" && cargo test --release --locked -p raster-diff --features gpu --test gpu --no-run \
        --message-format=json 2>/dev/null | python3 -c '
import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["target"]["name"] == "gpu":
        print(m["executable"])')
    [[ -n $test_bin ]] || die "could not build raster-diff's gpu test binary"
    cp "$repo/target/release/stylize" "$bundle/bin/stylize"
    cp "$repo/target/release/examples/unet_bench" "$bundle/bin/unet_bench"
    cp "$test_bin" "$bundle/bin/raster_gpu_tests"
    strip "$bundle/bin/"* 2>/dev/null || true
    cp -r "$repo/fixtures/models/tiny-if" "$repo/fixtures/models/tiny-if-fp16" "$bundle/fixtures/"
    cp "$repo/fixtures/meshes/bunny.obj" "$bundle/fixtures/"
    cp "$repo/scripts/realsize_check.py" "$repo/scripts/export_if_onnx.py" "$bundle/"
    if [[ -z $wheel ]]; then
        wheel=$(mktemp -d)/wheel
        python3 -m pip download --no-deps --only-binary=:all: --platform manylinux_2_28_x86_64 \
            --python-version 3.12 "onnxruntime-gpu==$ORT_VERSION" -d "$wheel" >&2
        wheel=$(ls "$wheel"/*.whl)
    fi
    local x
    x=$(mktemp -d)
    python3 -m zipfile -e "$wheel" "$x"
    local capi="$x/onnxruntime/capi"
    cp "$capi/libonnxruntime.so.$ORT_VERSION" "$capi/libonnxruntime_providers_shared.so" "$bundle/ort/"
    (cd "$bundle/ort" && sha256sum "libonnxruntime.so.$ORT_VERSION" libonnxruntime_providers_shared.so > SHA256SUMS)
    cmd_split "$capi/$PROVIDER" "$bundle/ort"
    rm -rf "$x"
    echo "bundle ready: $bundle ($(du -sh "$bundle" | cut -f1)); largest file $(find "$bundle" -type f -printf '%s %p\n' | sort -n | tail -1)"
}

# The nvidia-* wheels' lib folders (cuDNN, cuBLAS, the CUDA runtime, …) of python3, joined by ':'.
nvidia_lib_path() {
    python3 - <<'EOF' 2>/dev/null || true
import glob, os, site, sys
roots = [p for p in site.getsitepackages() + [site.getusersitepackages()] if os.path.isdir(p)]
dirs = sorted({d for r in roots for d in glob.glob(os.path.join(r, "nvidia", "*", "lib"))})
dirs += sorted({d for r in roots for d in glob.glob(os.path.join(r, "nvidia", "cu13", "lib"))})
print(":".join(dict.fromkeys(dirs)))
EOF
}

cmd_run() {
    [[ $# -ge 1 ]] || usage
    local bundle=$1 work="" only="" device=cuda:0
    shift
    while [[ $# -gt 0 ]]; do
        case $1 in
            --work) work=${2:?--work needs a directory}; shift 2 ;;
            --only) only=${2:?--only needs a step}; shift 2 ;;
            --device) device=${2:?--device needs cpu or cuda:N}; shift 2 ;;
            *) usage ;;
        esac
    done
    [[ -d $bundle ]] || die "no bundle directory $bundle (make it with \`gpu_check.sh pack\`)"
    [[ $device == cpu || $device =~ ^cuda:[0-9]+$ ]] || bad_arg "--device $device: cpu or cuda:N"
    if [[ -n $only && ! " ${STEPS[*]} " =~ \ $only\  ]]; then
        bad_arg "--only $only: one of ${STEPS[*]}"
    fi
    bundle=$(cd "$bundle" && pwd)
    work=${work:-$bundle/work}
    mkdir -p "$work/done"
    local bin=$bundle/bin failed=()
    for b in stylize unet_bench; do
        [[ -x $bin/$b ]] || die "$bin/$b is missing (run \`gpu_check.sh pack\` on a build machine)"
    done

    local ort_dir=$work/ort
    mkdir -p "$ort_dir"
    for f in "libonnxruntime.so.$ORT_VERSION" libonnxruntime_providers_shared.so; do
        [[ -f $bundle/ort/$f ]] || die "$bundle/ort/$f is missing"
        cp -u "$bundle/ort/$f" "$ort_dir/$f"
    done
    (cd "$ort_dir" && sha256sum --quiet -c "$bundle/ort/SHA256SUMS" --ignore-missing) \
        || die "ONNX Runtime files in $ort_dir do not match $bundle/ort/SHA256SUMS"
    export ORT_DYLIB_PATH=$ort_dir/libonnxruntime.so.$ORT_VERSION
    local nv
    nv=$(nvidia_lib_path)
    export LD_LIBRARY_PATH=$ort_dir${nv:+:$nv}${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
    local gpu=1
    if [[ $device == cpu ]] || ! command -v nvidia-smi > /dev/null || ! nvidia-smi -L > /dev/null 2>&1; then
        gpu=0
        say "no NVIDIA GPU here (or --device cpu): CPU fallbacks only; the GPU figures stay unmeasured"
        device=cpu
    fi

    step_wanted() { [[ -z $only || $only == "$1" ]] && { [[ -n $only ]] || [[ ! -e $work/done/$1 ]]; }; }
    pass() { touch "$work/done/$1"; say "$1: PASS"; }
    fail() { failed+=("$1"); say "$1: FAIL ($2)"; }

    if step_wanted setup; then
        say "setup: CUDA provider parts -> $ort_dir"
        if [[ $gpu == 1 ]]; then
            if cmd_reassemble "$bundle/ort" "$PROVIDER" "$ort_dir"; then
                "$bin/stylize" doctor --model "$bundle/fixtures/tiny-if" || true
                if "$bin/stylize" doctor --json | python3 -c '
import json, sys
d = json.load(sys.stdin)
ok = d["onnx_runtime"]["cuda_provider"]["state"] == "loads" and d["driver"]["gpus"]
sys.exit(0 if ok else 1)'; then
                    pass setup
                else
                    fail setup "stylize doctor does not see the CUDA provider loading and a GPU (its output above says why)"
                fi
            else
                fail setup "the CUDA provider could not be reassembled"
            fi
        else
            "$bin/stylize" doctor --model "$bundle/fixtures/tiny-if" || true
            say "setup: skipped the CUDA provider (no GPU)"
        fi
    fi

    if step_wanted agree; then
        say "agree: tiny IF on $device vs the CPU provider"
        local ok=1
        for m in tiny-if tiny-if-fp16; do
            for st in 1 2; do
                "$bin/unet_bench" --model "$bundle/fixtures/$m" --stage "$st" --device "$device" --batch 4 \
                    --compare-cpu || ok=0
            done
        done
        if [[ $ok == 1 && $gpu == 1 ]]; then pass agree; elif [[ $ok == 1 ]]; then say "agree: CPU vs CPU only (no GPU)"; else fail agree "see above"; fi
    fi

    if step_wanted throughput; then
        say "throughput: real-size random stage II (1.24 B parameters) on $device"
        local rs=$work/realsize
        if [[ ! -f $rs/onnx-fp16/manifest.toml ]]; then
            if [[ -d $bundle/wheels ]] && ! python3 -c 'import diffusers, onnx' 2>/dev/null; then
                python3 -m venv --system-site-packages "$work/venv"
                "$work/venv/bin/pip" install --no-index --find-links "$bundle/wheels" diffusers onnx onnxscript accelerate
                PY=$work/venv/bin/python
            else
                PY=python3
            fi
            "$PY" "$bundle/realsize_check.py" --work "$rs" --profiles fp16 --export-only \
                --min-available-gb 8 || true
        fi
        if [[ -f $rs/onnx-fp16/manifest.toml ]]; then
            if [[ $gpu == 1 ]]; then
                "$bin/unet_bench" --model "$rs/onnx-fp16" --stage 2 --device "$device" --batch 16 --px 256 \
                    --reps 5 --io-binding both --flop-per-sample 12.18e12 \
                    && "$bin/unet_bench" --model "$rs/onnx-fp16" --stage 2 --device "$device" --batch 16 \
                        --px 64 --reps 10 --io-binding on --flop-per-sample 0.77e12 \
                    && pass throughput || fail throughput "see above"
            else
                say "throughput: no GPU; one CPU call at 64 px instead (minutes)"
                "$bin/unet_bench" --model "$rs/onnx-fp16" --stage 2 --device cpu --batch 2 --px 64 --reps 1 \
                    --io-binding on --flop-per-sample 0.77e12 || true
            fi
        else
            fail throughput "the real-size models could not be built (needs torch, diffusers, onnx: BUNDLE/wheels)"
        fi
    fi

    if step_wanted run; then
        say "run: stylize run --prompt with the tiny models on $device"
        local out=$work/run-tiny start end
        start=$(date +%s.%N)
        if "$bin/stylize" run "$bundle/fixtures/bunny.obj" --prompt "a wooden bunny" \
            --model "$bundle/fixtures/tiny-if" --out "$out" --force \
            --set optim.iterations=4 --set run.checkpoint_every=0 --set run.preview_every=0 \
            --set run.turntable_gif_frames=0 --set run.snapshot_every=0 \
            --set "guidance.stage1_device=$device" --set "guidance.stage2_device=$device"; then
            end=$(date +%s.%N)
            say "run: 4 iterations in $(python3 -c "print(f'{$end - $start:.1f}')") s (wall, incl. loading)"
            if [[ $gpu == 1 ]]; then pass run; fi
        else
            fail run "stylize run failed"
        fi
    fi

    if step_wanted wgpu; then
        say "wgpu: renderer parity on the GPU (Vulkan)"
        if [[ ! -x $bin/raster_gpu_tests ]]; then
            fail wgpu "$bin/raster_gpu_tests is missing"
        elif [[ $gpu == 0 ]]; then
            say "wgpu: skipped (no GPU)"
        else
            command -v vulkaninfo > /dev/null && vulkaninfo --summary 2>/dev/null | grep -E "deviceName|driverName" || true
            local log=$work/wgpu.log
            if "$bin/raster_gpu_tests" --skip wgsl_shaders_validate_with_naga --test-threads 1 --nocapture > "$log" 2>&1 \
                && ! grep -q SKIPPED "$log"; then
                grep -E "test result|adapter" "$log" || true
                pass wgpu
            else
                tail -20 "$log"
                fail wgpu "the parity tests failed or found no adapter (SKIPPED): Vulkan loader or NVIDIA ICD missing?"
            fi
        fi
    fi

    if [[ ${#failed[@]} -gt 0 ]]; then
        say "failed: ${failed[*]}"
        exit 1
    fi
    say "done ($(ls "$work/done" | tr '\n' ' '))"
}

[[ $# -ge 1 ]] || usage
sub=$1
shift
case $sub in
    split) cmd_split "$@" ;;
    reassemble) cmd_reassemble "$@" ;;
    pack) cmd_pack "$@" ;;
    run) cmd_run "$@" ;;
    -h | --help) usage ;;
    *) echo "gpu_check: unknown command $sub" >&2; usage ;;
esac
