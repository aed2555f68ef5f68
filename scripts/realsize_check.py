#!/usr/bin/env python3
"""Real-size check of the ONNX path (issue 15): random-weight models of DeepFloyd IF-II-L's size,
exported with the project's exporter and run once through the `stylize` binary, with wall time and
peak RSS (`/usr/bin/time -v`) per step. Not part of CI: it needs ~10+ GB of RAM and 10-30 min of CPU.

    nice -n 10 .deps/pyenv/bin/python scripts/realsize_check.py --work /tmp/realsize \\
        --stylize target/release/stylize [--cpu-profile] [--ablation]

Steps (each its own process, so each peak RSS is that step's alone):

1. ``build``: writes random-weight models in diffusers' layout under WORK/diffusers: stage II with
   IF-II-L's size (the tiny stage-II config of export_if_onnx.py scaled to channels
   (320, 640, 1280, 1280), 4 layers per block, IF-II-L's attention/text widths: ~1.2 B parameters,
   ~2.4 GB in fp16), created on the meta device and materialised directly in fp16 (no fp32 copy);
   stage I and the T5 encoder tiny (T5 with IF's 4096-wide embeddings, so the real pipeline's shapes
   hold). IF-I-XL's size (4.3 B) is **not** built: on a 24 GB machine shared with other work its
   export and runtime would not fit beside everything else.
2. ``export-fp16``: ``export_if_onnx.py --from-pretrained ... --dtype fp16`` (with the check).
3. ``export-fp32`` (``--cpu-profile``): the same weights exported in fp32, the CPU profile.
4. ``embed``: ``stylize embed --force`` of the prompt (T5 alone), so that the guidance steps read the cache.
5. ``guidance ...``: ``stylize debug-guidance --stage2-weight 0.3`` on one random 512 px render (one
   view: stage I on 2 samples at 64 px, stage II on 2 samples -- cond and uncond -- at 256 px), with
   ONNX Runtime's default settings and with the low-memory ones (``SessionOptions::low_memory``: arena,
   memory pattern, pre-packing and graph optimizations off, one sample per call);
   ``--guidance-configs`` picks settings by name, ``--ablation`` also runs each setting alone.

Each step reports wall time, peak RSS, the 1-minute load average when it ended, and the ratio of its
peak RSS to the models it holds on disk (export: the stage-II model, the largest; guidance: the stage-I
and stage-II UNets; embed: the T5 encoder).

Refuses to start when MemAvailable is under ``--min-available-gb`` (default 16): other people's work
shares the machine.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

SCRIPT_DIR = Path(__file__).resolve().parent
REPO = SCRIPT_DIR.parent

# IF-II-L's UNet shape on the tiny stage-II block layout (export_if_onnx.build_tiny).
REALSIZE_STAGE2 = dict(
    block_out_channels=(320, 640, 1280, 1280),
    layers_per_block=4,
    norm_num_groups=32,
    attention_head_dim=64,
    cross_attention_dim=1280,
    addition_embed_type_num_heads=64,
)
TEXT_DIM = 4096  # T5-v1.1-XXL's width: the embeddings the real UNets take


def mem_available_gb() -> float:
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith("MemAvailable:"):
            return int(line.split()[1]) / 1e6 * 1.024
    return 0.0


def materialize_random(model_cls, config: dict, seed: int):
    """``model_cls(**config)`` with random weights, built on the meta device and materialised directly
    in fp16: every parameter is allocated once, in fp16, and initialised by its module's own
    ``reset_parameters`` (torch's default init), the few without one by a scaled normal draw."""
    import torch

    torch.manual_seed(seed)
    old = torch.get_default_dtype()
    torch.set_default_dtype(torch.float16)
    try:
        with torch.device("meta"):
            model = model_cls(**config)
    finally:
        torch.set_default_dtype(old)
    model = model.to_empty(device="cpu")
    done = set()
    with torch.no_grad():
        for m in model.modules():
            if hasattr(m, "reset_parameters") and callable(m.reset_parameters):
                m.reset_parameters()
                done.update(id(p) for p in m.parameters(recurse=False))
        # Parameters a module creates itself (e.g. diffusers' AttentionPooling.positional_embedding =
        # randn(1, d) / sqrt(d)) have no reset_parameters: the same scaled normal draw.
        for n, p in model.named_parameters():
            if id(p) not in done:
                p.normal_(0.0, p.shape[-1] ** -0.5)
                print(f"initialised {n} {tuple(p.shape)} ~ N(0, 1/{p.shape[-1]})", flush=True)
    if not all(torch.isfinite(p).all() for p in model.parameters()):
        raise SystemExit("error: a parameter is not finite after initialisation")
    for b in model.buffers():
        if not torch.isfinite(b).all():
            raise SystemExit("error: a buffer is not initialised")
    return model.eval()


def unet_tflop_per_sample(model_cls, config: dict, in_ch: int, px: int, class_label: bool) -> float:
    """FLOPs (multiply-adds count 2) of one sample through the UNet at ``px`` x ``px``, counted by
    PyTorch's FlopCounterMode on the meta device (no weights, no arithmetic)."""
    import torch
    from torch.utils.flop_counter import FlopCounterMode

    with torch.device("meta"):
        m = model_cls(**config)
        args = (torch.randn(1, in_ch, px, px), torch.tensor([20]))
        kw = {"encoder_hidden_states": torch.randn(1, 77, TEXT_DIM)}
        if class_label:
            kw["class_labels"] = torch.tensor([250])
    counter = FlopCounterMode(display=False)
    with counter, torch.no_grad():
        m(*args, **kw)
    return counter.get_total_flops() / 1e12


def build(work: Path, seed: int):
    """Step 1 (run in its own process)."""
    sys.path.insert(0, str(SCRIPT_DIR))
    import export_if_onnx as exp
    from diffusers import DDPMScheduler, UNet2DConditionModel
    from transformers import T5Config, T5EncoderModel

    out = work / "diffusers"
    s1, s2 = out / "stage1", out / "stage2"
    cfg2 = exp.tiny_unet_common(TEXT_DIM)
    cfg2.update(
        down_block_types=("ResnetDownsampleBlock2D",) * 3 + ("SimpleCrossAttnDownBlock2D",),
        up_block_types=("SimpleCrossAttnUpBlock2D",) + ("ResnetUpsampleBlock2D",) * 3,
        **REALSIZE_STAGE2,
    )
    config2 = dict(sample_size=256, in_channels=6, out_channels=6, class_embed_type="timestep", **cfg2)
    tflop = {f"stage2_tflop_per_sample_{px}px": unet_tflop_per_sample(UNet2DConditionModel, config2, 6, px, True)
             for px in (64, 256)}
    stage2 = materialize_random(UNet2DConditionModel, config2, seed + 2)
    n2 = sum(p.numel() for p in stage2.parameters())
    stage2.save_pretrained(s2 / "unet")
    del stage2
    stage1 = materialize_random(
        UNet2DConditionModel,
        dict(sample_size=64, in_channels=3, out_channels=6, **exp.tiny_unet_common(TEXT_DIM)),
        seed + 1,
    )
    n1 = sum(p.numel() for p in stage1.parameters())
    stage1.save_pretrained(s1 / "unet")
    del stage1
    t5 = materialize_random(T5EncoderModel, dict(config=T5Config(**{**exp.TINY_T5, "d_model": TEXT_DIM})), seed)
    n0 = sum(p.numel() for p in t5.parameters())
    t5.save_pretrained(s1 / "text_encoder")
    cfg = {k: v for k, v in exp.DEFAULT_SCHEDULER.items() if not k.startswith("_")}
    for d in (s1 / "scheduler", s2 / "scheduler", s2 / "image_noising_scheduler"):
        DDPMScheduler(**cfg).save_pretrained(d)
    info = {"stage2_params": n2, "stage1_params": n1, "text_encoder_params": n0, **tflop}
    (out / "params.json").write_text(json.dumps(info, indent=2) + "\n")
    print(json.dumps(info))


def weight_bytes(model_dir: Path, prefixes: tuple[str, ...]) -> int:
    """Bytes on disk of the exported models whose file names start with one of ``prefixes`` (the
    ``.onnx`` graphs and their ``.onnx.data`` external weights)."""
    return sum(f.stat().st_size for f in model_dir.iterdir() if f.name.startswith(prefixes))


def timed(label: str, cmd: list[str], log: Path, model_bytes: int | None = None) -> dict:
    """Runs ``cmd`` under ``/usr/bin/time -v``; returns wall seconds, peak RSS (GiB), the 1-minute load
    average at the end (other work on the machine), and with ``model_bytes`` the ratio peak RSS / those
    bytes on disk."""
    print(f"\n=== {label}: {' '.join(cmd)}", flush=True)
    t0 = time.monotonic()
    with open(log, "w") as f:
        proc = subprocess.run(["/usr/bin/time", "-v", *cmd], stdout=f, stderr=subprocess.STDOUT)
    wall = time.monotonic() - t0
    text = log.read_text()
    m = re.search(r"Maximum resident set size \(kbytes\): (\d+)", text)
    rss = int(m.group(1)) / (1 << 20) if m else float("nan")
    keep = [line for line in text.splitlines() if line.startswith(("[verify]", "[memory]", "[load]", "[ort]"))]
    tail = "\n".join(keep) if proc.returncode == 0 else text[-4000:]
    print(tail, flush=True)
    res = {"step": label, "wall_s": round(wall, 1), "peak_rss_gib": round(rss, 2), "rc": proc.returncode,
           "load_1min": round(os.getloadavg()[0], 1)}
    ratio = ""
    if model_bytes:
        res["model_gb"] = round(model_bytes / 1e9, 3)
        res["ratio"] = round(rss * (1 << 30) / model_bytes, 2)
        ratio = f" = {res['ratio']}x the {res['model_gb']} GB of models"
    print(f"=== {label}: rc {proc.returncode}, wall {wall:.1f} s, peak RSS {rss:.2f} GiB{ratio}, "
          f"load {res['load_1min']} (log {log})", flush=True)
    return res


def ort_call(model: Path, px: int, flags: list[str]):
    """One stage-II UNet call (cond + uncond: batch 2 at ``px``) in ONNX Runtime's Python binding (the
    same library version the binary loads), with the settings ``flags`` name -- ``no-arena``,
    ``no-memory-pattern``, ``no-prepacking``, ``no-graph-optimizations``, ``max-batch-1`` -- mirroring
    `SessionOptions`. Prints load and call time and the RSS after each."""
    import numpy as np
    import onnxruntime as ort

    def rss():
        status = Path("/proc/self/status").read_text()
        return int(re.search(r"VmRSS:\s+(\d+)", status).group(1)) / (1 << 20)

    so = ort.SessionOptions()
    so.enable_cpu_mem_arena = "no-arena" not in flags
    so.enable_mem_pattern = "no-memory-pattern" not in flags
    if "no-prepacking" in flags:
        so.add_session_config_entry("session.disable_prepacking", "1")
    if "no-graph-optimizations" in flags:
        so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_DISABLE_ALL
    t0 = time.monotonic()
    sess = ort.InferenceSession(str(model), so, providers=["CPUExecutionProvider"])
    print(f"[ort] load {time.monotonic() - t0:.1f} s, RSS {rss():.2f} GiB", flush=True)
    dt = np.float16 if sess.get_inputs()[0].type == "tensor(float16)" else np.float32
    rng = np.random.default_rng(0)
    feeds = {"sample": rng.standard_normal((2, 6, px, px)).astype(dt), "timestep": np.array([500, 500]),
             "encoder_hidden_states": rng.standard_normal((2, 77, TEXT_DIM)).astype(dt),
             "class_labels": np.array([250, 250])}
    t0 = time.monotonic()
    chunks = [slice(0, 1), slice(1, 2)] if "max-batch-1" in flags else [slice(0, 2)]
    outs = [sess.run(None, {k: v[c] for k, v in feeds.items()})[0] for c in chunks]
    out = np.concatenate(outs)
    print(f"[ort] call {time.monotonic() - t0:.1f} s ({px} px, batch 2 in {len(chunks)} call(s)), RSS {rss():.2f} GiB, "
          f"finite {bool(np.isfinite(out).all())}", flush=True)


def write_render(path: Path, seed: int):
    """One smooth random 512 x 512 RGB render in [0, 1], shape (1, 512, 512, 3) f32."""
    import numpy as np

    rng = np.random.default_rng(seed)
    coarse = rng.random((1, 8, 8, 3), dtype=np.float32)
    img = np.repeat(np.repeat(coarse, 64, axis=1), 64, axis=2)
    np.save(path, np.clip(img + 0.05 * rng.standard_normal(img.shape, dtype=np.float32), 0.0, 1.0))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--work", type=Path, default=Path("/tmp/realsize"), help="scratch directory (~10 GB of disk)")
    p.add_argument("--stylize", type=Path, default=REPO / "target" / "release" / "stylize", help="the binary")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--cpu-profile", action="store_true", help="also export and run the fp32 CPU profile")
    p.add_argument("--profiles", default=None, help="comma-separated export dtypes to use (overrides --cpu-profile)")
    p.add_argument("--ablation", action="store_true", help="also run each low-memory setting alone")
    p.add_argument("--guidance-configs", default=None,
                   help="';'-separated guidance settings by name (default: 'ORT defaults;low memory'; also "
                        "'low memory, graph optimizations on')")
    p.add_argument("--min-available-gb", type=float, default=16.0)
    p.add_argument("--threads", type=int, default=None, help="ONNX Runtime intra-op threads")
    p.add_argument("--skip-build", action="store_true", help="reuse WORK/diffusers")
    p.add_argument("--skip-export", action="store_true", help="reuse WORK/onnx-*")
    p.add_argument("--export-only", action="store_true", help="stop after the exports (no binary needed)")
    p.add_argument("--ort", action="store_true",
                   help="also time one stage-II UNet call in onnxruntime (Python) per setting, at 256 px")
    p.add_argument("--only-ort", action="store_true", help="only the --ort measurements (reuses WORK/onnx-*)")
    p.add_argument("--ort-px", type=int, default=256, help="image size of the --ort calls (256: stage II's own)")
    p.add_argument("--ort-settings", default=None,
                   help="comma-separated subset of the --ort settings by name (default: all)")
    p.add_argument("--build-only", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--ort-call", nargs="+", metavar=("MODEL", "FLAG"), help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.build_only:
        build(a.work, a.seed)
        return
    if a.ort_call:
        ort_call(Path(a.ort_call[0]), a.ort_px, a.ort_call[1:])
        return
    if a.only_ort:
        a.skip_build = a.skip_export = a.ort = True
        a.export_only = True
    avail = mem_available_gb()
    if avail < a.min_available_gb:
        raise SystemExit(f"error: MemAvailable is {avail:.1f} GB < {a.min_available_gb} GB; try again later")
    if not a.export_only and not a.stylize.is_file():
        raise SystemExit(f"error: no stylize binary at {a.stylize} (cargo build --release -p stylize-cli)")
    a.work.mkdir(parents=True, exist_ok=True)
    logs = a.work / "logs"
    logs.mkdir(exist_ok=True)
    py = sys.executable
    previous = a.work / "results.json"
    # A resumed run (--skip-build) keeps the earlier steps' results.
    results = json.loads(previous.read_text()) if a.skip_build and previous.is_file() else []

    def record(r):
        results.append(r)
        (a.work / "results.json").write_text(json.dumps(results, indent=2) + "\n")

    print(f"machine: {os.cpu_count()} CPUs, MemAvailable {avail:.1f} GB, load {os.getloadavg()}", flush=True)
    if not a.skip_build:
        record(timed("build random models", [py, __file__, "--build-only", "--work", str(a.work),
                                             "--seed", str(a.seed)], logs / "build.log"))
    d = a.work / "diffusers"
    print(f"parameters: {(d / 'params.json').read_text()}", flush=True)
    profiles = a.profiles.split(",") if a.profiles else ["fp16"] + (["fp32"] if a.cpu_profile else [])
    for dtype in profiles:
        out = a.work / f"onnx-{dtype}"
        if not a.skip_export:
            r = timed(f"export {dtype}", [py, str(SCRIPT_DIR / "export_if_onnx.py"), "--from-pretrained",
                                          str(d / "stage1"), str(out), "--stage2", str(d / "stage2"),
                                          "--dtype", dtype, "--name", f"realsize-{dtype}"],
                      logs / f"export-{dtype}.log")
            if r["rc"] == 0:  # the ratio to the largest model (stage II), the one that sets the peak
                stage2 = weight_bytes(out, ("unet_stage2",))
                r.update(model_gb=round(stage2 / 1e9, 3), ratio=round(r["peak_rss_gib"] * (1 << 30) / stage2, 2))
                print(f"=== export {dtype}: peak RSS = {r['ratio']}x the stage-II model ({r['model_gb']} GB)")
            record(r)
        sizes = {f.name: f.stat().st_size for f in out.iterdir() if f.name.startswith("unet_stage2")}
        print(f"stage II files ({dtype}): {sizes}", flush=True)
    ort_settings = [("ORT defaults", []), ("arena off", ["no-arena"]), ("memory pattern off", ["no-memory-pattern"]),
                    ("pre-packing off", ["no-prepacking"]), ("graph optimizations off", ["no-graph-optimizations"]),
                    ("low memory", ["no-arena", "no-memory-pattern", "no-prepacking", "no-graph-optimizations",
                                    "max-batch-1"])]
    if a.ort_settings:
        wanted = [w.strip() for w in a.ort_settings.split(",")]
        ort_settings = [x for x in ort_settings if x[0] in wanted]
    for dtype in profiles if a.ort else []:
        for name, flags in ort_settings:
            model = a.work / f"onnx-{dtype}" / "unet_stage2.onnx"
            slug = re.sub(r"[^a-z0-9]+", "-", name.lower())
            record(timed(f"onnxruntime stage-II call {dtype} at {a.ort_px} px, {name}",
                         [py, __file__, "--ort-px", str(a.ort_px), "--ort-call", str(model), *flags],
                         logs / f"ort-{dtype}-{a.ort_px}px-{slug}.log"))
    render = a.work / "render.npy"
    write_render(render, a.seed)
    low = ["--no-arena", "--no-memory-pattern", "--no-prepacking", "--no-graph-optimizations", "--max-batch", "1"]
    configs = [("ORT defaults", []), ("low memory", low)]
    # The low-memory settings but with graph optimizations (fusions: fewer intermediates; an fp32 model has
    # no fp16->fp32 weight casts to fold, so the weights stay as stored).
    extra = [("low memory, graph optimizations on", low[:3] + ["--max-batch", "1"])]
    if a.guidance_configs:
        wanted = [w.strip() for w in a.guidance_configs.split(";")]
        configs = [c for c in configs + extra if c[0] in wanted]
        if len(configs) != len(wanted):
            raise SystemExit(f"error: --guidance-configs: unknown name in {wanted}")
    if a.ablation:
        configs += [("arena off", ["--no-arena"]), ("memory pattern off", ["--no-memory-pattern"]),
                    ("pre-packing off", ["--no-prepacking"]), ("graph optimizations off", ["--no-graph-optimizations"]),
                    ("max batch 1", ["--max-batch", "1"])]
    for dtype in profiles if not a.export_only else []:
        models = a.work / f"onnx-{dtype}"
        # Encode the prompt once, so that every guidance step reads the cache and measures the UNets alone.
        record(timed(f"embed {dtype}", [str(a.stylize), "embed", "--model", str(models), "--prompt", "a wooden chair",
                                        "--cache", str(a.work / "cache"), "--force"], logs / f"embed-{dtype}.log",
                     weight_bytes(models, ("text_encoder",))))
        unets = weight_bytes(models, ("unet_stage1", "unet_stage2"))
        for name, flags in configs:
            cmd = [str(a.stylize), "debug-guidance", "--model", str(a.work / f"onnx-{dtype}"), "--images",
                   str(render), "--prompt", "a wooden chair", "--seed", "0", "--stage2-weight", "0.3",
                   "--cache", str(a.work / "cache"), "--out", str(a.work / f"dump-{dtype}.npz"), *flags]
            if a.threads:
                cmd += ["--threads", str(a.threads)]
            slug = re.sub(r"[^a-z0-9]+", "-", name.lower())
            record(timed(f"guidance {dtype}, {name}", cmd, logs / f"guidance-{dtype}-{slug}.log", unets))
    print("\n| step | wall (s) | peak RSS (GiB) | models (GB) | peak / models | load | rc |\n|---|---|---|---|---|---|---|")
    for r in results:
        print(f"| {r['step']} | {r['wall_s']} | {r['peak_rss_gib']} | {r.get('model_gb', '')} | {r.get('ratio', '')} | "
              f"{r.get('load_1min', '')} | {r['rc']} |")
    if any(r["rc"] != 0 for r in results):
        raise SystemExit("error: a step failed (see its log)")


if __name__ == "__main__":
    main()
