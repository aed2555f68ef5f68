#!/usr/bin/env python3
"""Export DeepFloyd IF (stage I UNet, stage II UNet, T5 encoder) to ONNX for `diffusion-onnx`.

Two modes, one output layout (``manifest.toml`` + ``.onnx`` files, see docs/models.md):

  --tiny OUT_DIR
      Randomly initialised, seeded, *tiny* models with IF's architecture (diffusers'
      ``UNet2DConditionModel`` configured like IF-I-XL / IF-II-L, transformers' ``T5EncoderModel``
      configured like T5-v1.1), plus PyTorch reference inputs/outputs under ``reference/``.
      Used as test fixtures (fixtures/models/tiny-if). No weights are downloaded.

  --from-pretrained STAGE1_DIR_OR_ID OUT_DIR [--stage2 DIR_OR_ID] [--text-encoder DIR_OR_ID]
      The real models for users who have them (DeepFloyd/IF-I-XL-v1.0, DeepFloyd/IF-II-L-v1.0;
      the T5-v1.1-XXL encoder is the ``text_encoder`` subfolder of the stage-I repository).
      ``--dtype fp16`` (default, as IF runs) or ``fp32``. Models over 2 GB are written with ONNX
      external data (``<file>.onnx.data`` beside the ``.onnx``); the manifest lists those files.

Every exported model is run once in ONNX Runtime and in PyTorch on the same random inputs; the
maximum absolute difference is printed and the script fails above the tolerance
(fp32: 1e-4 + 1e-4 * max|torch output|; fp16: 1e-2 + 1e-2 * max|torch output|). The PyTorch side runs
in fp32 (one layer upcast at a time) at a small size (stage I 32 px, stage II 64 px, batch 2): minutes,
not hours, at IF scale. ``--skip-check`` skips it with a loud warning.

Needs: torch (CPU is enough), diffusers, transformers, onnx, onnxscript, onnxruntime, numpy, tokenizers.
"""

from __future__ import annotations

import argparse
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

# Shared with the CLIP exporter (this directory is on sys.path when a script here runs).
import onnx_export_common as common
from onnx_export_common import export_module, external_files

TOKENIZER_JSON = common.ASSETS / "t5_tokenizer.json"
MAX_TOKENS = 77
FORMAT_VERSION = 1

# (absolute, relative to max |reference|), against the fp32 PyTorch reference. fp16: the tiny fixtures and
# the IF-II-L-size random UNet differ by ~1e-3 at max |y| ~ 1.5 (docs/models.md); a single changed weight
# of the output convolution gives ~9e-2 (scripts/tests/test_export_check.py).
TOLERANCE = {"fp32": (1e-4, 1e-4), "fp16": (1e-2, 1e-2)}


# --------------------------------------------------------------------------------------------
# wrappers: fixed positional signatures with the input names the manifest declares
# --------------------------------------------------------------------------------------------


def _torch():
    import torch

    return torch


def make_wrappers():
    torch = _torch()

    class Stage1(torch.nn.Module):
        def __init__(self, unet):
            super().__init__()
            self.unet = unet

        def forward(self, sample, timestep, encoder_hidden_states):
            return self.unet(sample, timestep, encoder_hidden_states=encoder_hidden_states, return_dict=False)[0]

    class Stage2(torch.nn.Module):
        def __init__(self, unet):
            super().__init__()
            self.unet = unet

        def forward(self, sample, timestep, encoder_hidden_states, class_labels):
            return self.unet(
                sample,
                timestep,
                encoder_hidden_states=encoder_hidden_states,
                class_labels=class_labels,
                return_dict=False,
            )[0]

    class TextEncoder(torch.nn.Module):
        def __init__(self, t5):
            super().__init__()
            self.t5 = t5

        def forward(self, input_ids, attention_mask):
            return self.t5(input_ids=input_ids, attention_mask=attention_mask).last_hidden_state

    return Stage1, Stage2, TextEncoder


# --------------------------------------------------------------------------------------------
# tiny models with IF's architecture
# --------------------------------------------------------------------------------------------

TINY_T5 = dict(
    vocab_size=32128,  # T5 vocabulary size (the tokenizer's 32,100 ids + 28 unused), as T5-v1.1
    d_model=8,
    d_kv=4,
    d_ff=16,
    num_layers=1,
    num_heads=2,
    relative_attention_num_buckets=32,
    relative_attention_max_distance=128,
    feed_forward_proj="gated-gelu",  # T5-v1.1
    dropout_rate=0.0,
    tie_word_embeddings=False,
)


def tiny_unet_common(text_dim: int) -> dict:
    """Shared shape of IF's UNets, scaled down: ResNet down/up blocks, simple cross-attention,
    text cross-attention through ``encoder_hid_dim`` (text_proj) and ``addition_embed_type="text"``."""
    return dict(
        down_block_types=("ResnetDownsampleBlock2D", "SimpleCrossAttnDownBlock2D"),
        up_block_types=("SimpleCrossAttnUpBlock2D", "ResnetUpsampleBlock2D"),
        mid_block_type="UNetMidBlock2DSimpleCrossAttn",
        block_out_channels=(16, 32),
        layers_per_block=1,
        norm_num_groups=4,
        attention_head_dim=8,
        cross_attention_dim=32,
        encoder_hid_dim=text_dim,
        encoder_hid_dim_type="text_proj",
        addition_embed_type="text",
        addition_embed_type_num_heads=2,
        act_fn="gelu",
        resnet_time_scale_shift="scale_shift",
        resnet_skip_time_act=True,
        resnet_out_scale_factor=1.414,
        only_cross_attention=False,
        upcast_attention=False,
        use_linear_projection=False,
    )


def build_tiny(seed: int):
    torch = _torch()
    from diffusers import UNet2DConditionModel
    from transformers import T5Config, T5EncoderModel

    torch.manual_seed(seed)
    t5 = T5EncoderModel(T5Config(**TINY_T5)).eval()
    text_dim = TINY_T5["d_model"]

    torch.manual_seed(seed + 1)
    stage1 = UNet2DConditionModel(
        sample_size=64, in_channels=3, out_channels=6, **tiny_unet_common(text_dim)
    ).eval()

    torch.manual_seed(seed + 2)
    # Stage II works at 256 px: like IF-II, attention only at the coarsest level (here 32 px), after
    # three ResNet downsampling blocks -- attention at 128 px would need ~70 GB for a batch of 16.
    common2 = tiny_unet_common(text_dim)
    common2.update(
        down_block_types=("ResnetDownsampleBlock2D",) * 3 + ("SimpleCrossAttnDownBlock2D",),
        up_block_types=("SimpleCrossAttnUpBlock2D",) + ("ResnetUpsampleBlock2D",) * 3,
        block_out_channels=(8, 16, 16, 32),
    )
    stage2 = UNet2DConditionModel(
        sample_size=256,
        in_channels=6,
        out_channels=6,
        class_embed_type="timestep",  # IF-II: the noise level of the upsampled low-res image
        **common2,
    ).eval()
    return t5, stage1, stage2


# --------------------------------------------------------------------------------------------
# export + verification
# --------------------------------------------------------------------------------------------


def tokenize(prompts: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """T5 tokenization as the Rust side does it: lower-case + strip, content truncated to 76 tokens,
    then `</s>` (1), then padding (0) to 77 -- as HF's T5 tokenizer with truncation and max_length."""
    from tokenizers import Tokenizer

    tok = Tokenizer.from_file(str(TOKENIZER_JSON))
    ids = np.zeros((len(prompts), MAX_TOKENS), dtype=np.int64)
    mask = np.zeros((len(prompts), MAX_TOKENS), dtype=np.int64)
    for i, p in enumerate(prompts):
        enc = list(tok.encode(p.lower().strip(), add_special_tokens=False).ids)
        while enc and enc[-1] == 1:
            enc.pop()
        enc = enc[: MAX_TOKENS - 1] + [1]
        ids[i, : len(enc)] = enc
        mask[i, : len(enc)] = 1
    return ids, mask


def verify(path: Path, module, feeds: dict[str, np.ndarray], dtype: str, label: str) -> np.ndarray:
    """The exporter's check (see :func:`onnx_export_common.verify`): ``module`` computed in fp32 against
    the ONNX model at ``path``."""
    atol, rtol = TOLERANCE[dtype]
    return common.verify(path, module, feeds, atol, rtol, label)


def free_memory():
    """Returns what the previous model held to the system before the next one is loaded: collects
    cycles, then asks glibc to give freed heap memory back (``malloc_trim``: without it a freed 5 GB
    fp32 model stayed resident after an export and the next step's memory came on top)."""
    import ctypes
    import gc

    gc.collect()
    torch = _torch()
    if torch.cuda.is_available():
        torch.cuda.empty_cache()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


@dataclass
class StageSpec:
    key: str
    file: str
    in_channels: int
    out_channels: int
    sample_size: int
    class_labels: bool
    external: list[str] = field(default_factory=list)


def scheduler_toml(cfg: dict) -> str:
    keep = [
        "num_train_timesteps",
        "beta_schedule",
        "beta_start",
        "beta_end",
        "variance_type",
        "prediction_type",
        "clip_sample",
        "thresholding",
    ]
    lines = [f'name = "{cfg.get("_class_name", "DDPMScheduler")}"']
    for k in keep:
        if k in cfg and cfg[k] is not None:
            v = cfg[k]
            lines.append(f"{k} = {json.dumps(v) if not isinstance(v, bool) else str(v).lower()}")
    return "\n".join(lines)


DEFAULT_SCHEDULER = {
    "_class_name": "DDPMScheduler",
    "num_train_timesteps": 1000,
    "beta_schedule": "squaredcos_cap_v2",
    "variance_type": "learned_range",
    "prediction_type": "epsilon",
    "clip_sample": True,
    "thresholding": False,
}


def write_manifest(
    out: Path,
    name: str,
    description: str,
    dtype: str,
    text: dict | None,
    stages: list[StageSpec],
    schedulers: dict[str, dict],
    stage2_noising: dict | None,
):
    lines = [
        "# diffusion-onnx model directory manifest (see docs/models.md)",
        f"format_version = {FORMAT_VERSION}",
        f'name = "{name}"',
        f"description = {json.dumps(description)}",
        "",
    ]
    if text is not None:
        lines += [
            "[text_encoder]",
            f'file = "{text["file"]}"',
            f"external_data = {json.dumps(text['external'])}",
            f'dtype = "{dtype}"',
            f"max_tokens = {MAX_TOKENS}",
            f"embedding_dim = {text['dim']}",
            'tokenizer = "builtin:t5"',
            'input_ids = "input_ids"',
            'attention_mask = "attention_mask"',
            'output = "last_hidden_state"',
            "",
        ]
    lines += [
        "[embeddings]",
        f"dim = {text['dim'] if text else 4096}",
        f"tokens = {MAX_TOKENS}",
    ]
    if text is not None and text.get("uncond"):
        lines.append(f'uncond = "{text["uncond"]}"')
    else:
        lines.append('uncond = "builtin:if-t5-v1_1-xxl-empty"')
    lines.append("")
    for s in stages:
        lines += [
            f"[{s.key}]",
            f'file = "{s.file}"',
            f"external_data = {json.dumps(s.external)}",
            f'dtype = "{dtype}"',
            f"in_channels = {s.in_channels}",
            f"out_channels = {s.out_channels}",
            f"sample_size = {s.sample_size}",
            'sample = "sample"',
            'timestep = "timestep"',
            'encoder_hidden_states = "encoder_hidden_states"',
        ]
        if s.class_labels:
            lines.append('class_labels = "class_labels"')
        lines += ['output = "noise_pred"', "", f"[{s.key}.scheduler]", scheduler_toml(schedulers[s.key]), ""]
        if s.class_labels and stage2_noising is not None:
            lines += [f"[{s.key}.noising_scheduler]", scheduler_toml(stage2_noising), ""]
    (out / "manifest.toml").write_text("\n".join(lines))


@dataclass
class ExportContext:
    """What every model's export shares: output directory, float type, RNG for the check inputs,
    external-data policy, and whether to keep reference data (tiny fixtures) or check at all."""

    out: Path
    dtype: str
    seed: int
    big: bool
    save_reference: bool
    check: bool = True
    # Per-phase peak RSS (run_pretrained turns it on; None: not sampled).
    memory: common.MemoryPhases | None = None
    # Load, export and compute the PyTorch reference of each model in a forked child process, which exits
    # before this process runs ONNX Runtime's check (run_pretrained turns it on; see in_child).
    isolate: bool = False
    rng: np.random.Generator = field(init=False)

    def __post_init__(self):
        self.out.mkdir(parents=True, exist_ok=True)
        self.rng = np.random.default_rng(self.seed)
        if self.save_reference:
            (self.out / "reference").mkdir(exist_ok=True)

    def phase(self, name: str):
        """Marks the start of an export phase for the per-phase memory report."""
        if self.memory is not None:
            self.memory.phase(name)

    @property
    def np_dtype(self):
        return np.float16 if self.dtype == "fp16" else np.float32

    def save(self, name: str, arr: np.ndarray):
        if self.save_reference:
            np.save(self.out / "reference" / f"{name}.npy", arr)

    def check_px(self, key: str) -> int:
        """Spatial size of the check batch. The tiny fixtures keep their 64 px references; real models
        are checked small (the graph has dynamic spatial axes): 32 px for stage I (3 downsamplings in
        IF-I: 4 px at the coarsest level), 64 px for stage II (8 px there) -- 1/16 of a 256 px call."""
        if self.save_reference:
            return 64
        return 32 if key == "stage1" else 64


PROMPTS = ["a photo of a cat", "  A Wooden CHAIR, Ornate!  "]


def check(path: Path, reference: np.ndarray, feeds: dict[str, np.ndarray], dtype: str, label: str):
    """The ONNX model at ``path`` against the fp32 PyTorch ``reference`` on ``feeds``."""
    atol, rtol = TOLERANCE[dtype]
    common.check_close(common.onnx_run(path, feeds), reference, atol, rtol, label)


def report_memory(label: str, ctx: ExportContext | None = None):
    """Peak RSS so far (includes file-backed pages: the checkpoint and the written external data, which
    the kernel can drop under pressure), the anonymous part now, and (when ``ctx`` samples memory) the
    peak of each phase so far: load, export (trace, translate, optimize, save), PyTorch reference, check."""
    anon, file = common.rss_now_gib()
    print(f"[memory] after {label}: peak RSS of this process so far {common.peak_rss_gib():.2f} GiB; "
          f"now: anonymous {anon:.2f} GiB, file-backed {file:.2f} GiB", flush=True)
    if ctx is not None and ctx.memory is not None:
        print(f"[memory] peak RSS per phase (GiB): {ctx.memory.summary()}", flush=True)


def export_text_encoder(load, ctx: ExportContext) -> tuple[dict, np.ndarray]:
    """Exports (and checks) the T5 encoder ``load()`` returns; returns the manifest entry and the
    prompts' embeddings (conditioning for the UNet checks, computed in fp32). The model's weights are
    freed (:func:`onnx_export_common.release_weights`: the module is unusable afterwards) before ONNX
    Runtime loads the export for the check; with ``ctx.isolate`` the model side runs in a child process
    (:func:`in_child`)."""
    text, emb, feeds = in_child(ctx, _text_encoder_torch_side, load, ctx)
    path = ctx.out / text["file"]
    if ctx.check:
        ctx.phase("text_encoder check")
        check(path, emb, feeds, ctx.dtype, "text_encoder")
    ctx.save("t5_input_ids", feeds["input_ids"])
    ctx.save("t5_attention_mask", feeds["attention_mask"])
    ctx.save("t5_last_hidden_state", emb.astype(np.float32))
    report_memory("text_encoder", ctx)
    return text, emb


def _text_encoder_torch_side(load, ctx: ExportContext) -> tuple[dict, np.ndarray, dict]:
    """:func:`export_text_encoder` up to the check: load, export, fp32 reference, free the weights."""
    torch = _torch()
    _, _, TextEncoder = make_wrappers()
    ctx.phase("text_encoder load")
    enc = TextEncoder(load()).eval()
    ctx.phase("text_encoder export")
    text_dim = enc.t5.config.d_model
    ids, mask = tokenize(PROMPTS)
    path = ctx.out / "text_encoder.onnx"
    export_module(enc, (torch.from_numpy(ids), torch.from_numpy(mask)), ["input_ids", "attention_mask"],
                  "last_hidden_state", path, {"input_ids": [0], "attention_mask": [0]}, ctx.big)
    text = {"file": path.name, "external": external_files(path), "dim": text_dim}
    # The unconditional embedding: this encoder's output for the empty prompt, in the model's dtype.
    # The real T5-v1.1-XXL (dim 4096) uses IF's own shipped
    # empty-prompt vector instead (builtin).
    if ctx.save_reference or text_dim != 4096:
        e_ids, e_mask = tokenize([""])
        with torch.no_grad():
            uncond = enc(torch.from_numpy(e_ids), torch.from_numpy(e_mask))[0].float().numpy()
        np.save(ctx.out / "uncond_embedding.npy", uncond.astype(np.float32 if ctx.dtype == "fp32" else np.float16))
        text["uncond"] = "uncond_embedding.npy"
    feeds = {"input_ids": ids, "attention_mask": mask}
    # The reference (fp32) also gives the UNet checks their conditioning, so it runs even without the check.
    ctx.phase("text_encoder reference")
    emb = common.torch_reference(enc, feeds)
    common.release_weights(enc)
    del enc
    free_memory()
    return text, emb, feeds


def export_unet(key: str, load, cond: np.ndarray, ctx: ExportContext) -> StageSpec:
    """Exports (and checks) the UNet ``load()`` returns (``key`` "stage1" or "stage2") with ``cond``
    (2, 77, D) as the check's text conditioning. The check's PyTorch reference runs first (computed in
    fp32, small size); the model's weights are then freed (:func:`onnx_export_common.release_weights`:
    the module is unusable afterwards) before ONNX Runtime loads the export; with ``ctx.isolate`` the
    model side runs in a child process (:func:`in_child`)."""
    spec, feeds, ref = in_child(ctx, _unet_torch_side, key, load, cond, ctx)
    if ref is not None:
        ctx.phase(f"{key} check")
        check(ctx.out / spec.file, ref, feeds, ctx.dtype, f"unet_{key}")
        for n, v in feeds.items():
            ctx.save(f"{key}_{n}", v)
        ctx.save(f"{key}_noise_pred", ref.astype(np.float32))
    report_memory(f"unet_{key}", ctx)
    return spec


def _unet_torch_side(key: str, load, cond: np.ndarray, ctx: ExportContext):
    """:func:`export_unet` up to the check: load, export, fp32 reference (None without the check), free
    the weights; returns the manifest entry, the check's feeds and the reference."""
    torch = _torch()
    Stage1, Stage2, _ = make_wrappers()
    has_class = key == "stage2"
    ctx.phase(f"{key} load")
    mod = (Stage2 if has_class else Stage1)(load()).eval()
    config = mod.unet.config
    in_ch, out_ch, sample_size = int(config.in_channels), int(config.out_channels), int(config.sample_size)
    px = ctx.check_px(key)
    cond = cond.astype(ctx.np_dtype)
    sample = ctx.rng.standard_normal((2, in_ch, px, px)).astype(ctx.np_dtype)
    timestep = np.array([20, 980], dtype=np.int64)
    feeds = {"sample": sample, "timestep": timestep, "encoder_hidden_states": cond}
    names = ["sample", "timestep", "encoder_hidden_states"]
    dyn = {"sample": [0, 2, 3], "timestep": [0], "encoder_hidden_states": [0]}
    if has_class:
        feeds["class_labels"] = np.array([250, 0], dtype=np.int64)
        names.append("class_labels")
        dyn["class_labels"] = [0]
    path = ctx.out / f"unet_{key}.onnx"
    ctx.phase(f"{key} export")
    export_module(mod, tuple(torch.from_numpy(v) for v in feeds.values()), names, "noise_pred", path, dyn, ctx.big)
    free_memory()  # what the export traced and wrote
    ctx.phase(f"{key} reference")
    ref = common.torch_reference(mod, feeds) if ctx.check else None
    common.release_weights(mod)  # before ONNX Runtime maps the exported weights (see release_weights)
    del mod
    free_memory()
    return StageSpec(key, path.name, in_ch, out_ch, sample_size, has_class, external_files(path)), feeds, ref


def in_child(ctx: ExportContext, fn, *args):
    """``fn(*args)``, in a forked child process when ``ctx.isolate`` (else here), returning its result.

    Why a child: after ``torch.onnx.export`` some of the module's tensors stay referenced from inside
    torch (not reachable from Python's garbage collector), and since the weights of a checkpoint loaded
    with ``low_cpu_mem_usage`` are views of one memory-mapped file, a few of them keep the whole mapping
    -- the model's size in resident, file-backed pages -- alive; ONNX Runtime's check then mapped the
    exported weights on top (an IF-II-L-size fp16 UNet: 6.6 GiB peak, 2.9x the model, with
    :func:`onnx_export_common.release_weights` alone; docs/models.md). A child that exits returns all of
    it. The child's RNG draws, external-data decision and per-phase memory peaks are carried back."""
    if not ctx.isolate:
        return fn(*args)
    import multiprocessing
    import pickle
    import traceback

    recv, send = multiprocessing.get_context("fork").Pipe(duplex=False)
    pid = os.fork()
    if pid == 0:  # child: run, send the result, exit without running the parent's cleanup
        code = 0
        try:
            recv.close()
            if ctx.memory is not None:  # the sampling thread does not survive fork
                ctx.memory = common.MemoryPhases()
            result = fn(*args)
            peaks = dict(ctx.memory.peaks) if ctx.memory is not None else {}
            send.send_bytes(pickle.dumps(("ok", result, ctx.rng.bit_generator.state, ctx.big, peaks)))
        except BaseException as e:  # noqa: BLE001 - reported by the parent
            code = 1
            try:
                send.send_bytes(pickle.dumps(("error", f"{e!r}\n{traceback.format_exc()}", None, None, None)))
            except Exception:  # noqa: BLE001
                pass
        finally:
            send.close()
            os._exit(code)
    send.close()
    try:
        status, result, rng_state, big, peaks = pickle.loads(recv.recv_bytes())
    except EOFError:
        status, result = "error", "the child process died without a result (killed for memory?)"
    finally:
        recv.close()
        _, wait_status = os.waitpid(pid, 0)
    if status != "ok":
        raise SystemExit(f"error: exporting in the child process failed (exit status {wait_status}): {result}")
    ctx.rng.bit_generator.state = rng_state
    ctx.big = big
    if ctx.memory is not None:
        ctx.memory.peaks.update({f"{name} [child]": v for name, v in peaks.items()})
    return result


def export_all(t5, stage1, stage2, out: Path, dtype: str, seed: int, big: bool, save_reference: bool):
    """All three models already in memory (the tiny fixtures; each has its weights freed once
    exported); the real models go one at a time through :func:`run_pretrained`."""
    ctx = ExportContext(out, dtype, seed, big, save_reference)
    text, emb = export_text_encoder(lambda: t5, ctx)
    stages = [export_unet("stage1", lambda: stage1, emb, ctx), export_unet("stage2", lambda: stage2, emb, ctx)]
    return text, stages


def versions() -> dict:
    return common.versions({
        "torch": "torch",
        "diffusers": "diffusers",
        "transformers": "transformers",
        "onnx": "onnx",
        "onnxscript": "onnxscript",
        "onnxruntime": "onnxruntime",
    })


def run_tiny(out: Path, seed: int):
    t5, stage1, stage2 = build_tiny(seed)
    text, stages = export_all(t5, stage1, stage2, out, "fp32", seed, big=False, save_reference=True)
    schedulers = {"stage1": DEFAULT_SCHEDULER, "stage2": DEFAULT_SCHEDULER}
    write_manifest(
        out,
        name=f"tiny-if-seed{seed}",
        description="Randomly initialised tiny models with DeepFloyd IF's architecture (test fixture, not a real model)",
        dtype="fp32",
        text=text,
        stages=stages,
        schedulers=schedulers,
        stage2_noising=DEFAULT_SCHEDULER,
    )
    (out / "versions.json").write_text(json.dumps({"seed": seed, **versions()}, indent=2) + "\n")
    print(f"wrote {out}")


def save_tiny_diffusers(out: Path, seed: int):
    """Write the tiny models in diffusers' on-disk layout (``stage1/{unet,text_encoder,scheduler}``,
    ``stage2/{unet,scheduler,image_noising_scheduler}``) so ``--from-pretrained`` can be exercised
    without the real weights."""
    from diffusers import DDPMScheduler

    t5, stage1, stage2 = build_tiny(seed)
    s1, s2 = out / "stage1", out / "stage2"
    stage1.save_pretrained(s1 / "unet")
    t5.save_pretrained(s1 / "text_encoder")
    stage2.save_pretrained(s2 / "unet")
    cfg = {k: v for k, v in DEFAULT_SCHEDULER.items() if not k.startswith("_")}
    DDPMScheduler(**cfg).save_pretrained(s1 / "scheduler")
    DDPMScheduler(**cfg).save_pretrained(s2 / "scheduler")
    DDPMScheduler(**cfg).save_pretrained(s2 / "image_noising_scheduler")
    print(f"wrote {s1} and {s2}")


def load_scheduler_config(src: str, subfolder: str) -> dict:
    from diffusers import DDPMScheduler

    try:
        return dict(DDPMScheduler.load_config(src, subfolder=subfolder))
    except Exception as e:  # noqa: BLE001 - fall back, but say so
        print(f"warning: no {subfolder} config in {src} ({e}); writing IF's documented DDPM squaredcos_cap_v2")
        return DEFAULT_SCHEDULER


def require_accelerate():
    """Low-memory loading (``low_cpu_mem_usage``: weights go straight from the checkpoint into an
    empty, meta-device model instead of into a randomly initialised one) needs ``accelerate``."""
    try:
        import accelerate  # noqa: F401
    except ImportError:
        raise SystemExit(
            "error: the `accelerate` package is missing; it is needed to load multi-GB models without a second "
            "copy of their weights. Install scripts/requirements-export.txt (pip install -r ...)."
        ) from None


def checkpoint_bytes(src: str, subfolder: str | None) -> int | None:
    """Size of a local diffusers/transformers checkpoint's weight files (None for a hub id): decides
    whether the export needs ONNX external data before the model is loaded."""
    d = Path(src) / subfolder if subfolder else Path(src)
    if not d.is_dir():
        return None
    return sum(f.stat().st_size for f in d.iterdir() if f.suffix in (".safetensors", ".bin"))


def run_pretrained(stage1_src: str, out: Path, dtype: str, stage2_src: str, text_src: str | None, seed: int,
                   skip_text: bool, name: str | None, external: str = "auto", check: bool = True):
    """Exports the real models **one at a time**: each is loaded with low-memory initialisation in the
    export dtype, exported with external data straight from its parameters, checked (fp32 PyTorch
    reference at a small size, then ONNX Runtime), and released before the next one is loaded, so the
    peak memory is set by the largest model alone."""
    torch = _torch()
    from diffusers import UNet2DConditionModel
    from transformers import T5EncoderModel

    require_accelerate()
    if not check:
        common.warn_skip_check()
    tdtype = torch.float16 if dtype == "fp16" else torch.float32
    low_mem = dict(torch_dtype=tdtype, low_cpu_mem_usage=True)

    def n_bytes(m) -> int:
        return sum(p.numel() * p.element_size() for p in m.parameters())

    def needs_external(m) -> bool:
        return external == "always" or n_bytes(m) > 1.9e9

    def loader(load_fn):
        """Loads, then decides external data per model (protobuf's 2 GB limit)."""
        def load():
            m = load_fn().eval()
            ctx.big = needs_external(m)
            print(f"[load] {m.__class__.__name__}: {n_bytes(m) / 1e9:.2f} GB of {dtype} parameters; "
                  f"external data: {ctx.big}; peak RSS so far {common.peak_rss_gib():.2f} GiB", flush=True)
            return m
        return load

    ctx = ExportContext(out, dtype, seed, big=external == "always", save_reference=False, check=check,
                        memory=common.MemoryPhases(), isolate=True)
    text = None
    if not skip_text:
        if text_src is None:
            load_t5 = lambda: T5EncoderModel.from_pretrained(stage1_src, subfolder="text_encoder", **low_mem)  # noqa: E731
        else:
            load_t5 = lambda: T5EncoderModel.from_pretrained(text_src, **low_mem)  # noqa: E731
        text, cond = export_text_encoder(loader(load_t5), ctx)
    else:
        cfg = UNet2DConditionModel.load_config(stage1_src, subfolder="unet")
        text_dim = int(cfg.get("encoder_hid_dim") or 4096)
        cond = ctx.rng.standard_normal((2, MAX_TOKENS, text_dim)).astype(np.float32)
    free_memory()
    stages = []
    for key, src in (("stage1", stage1_src), ("stage2", stage2_src)):
        load = loader(lambda src=src: UNet2DConditionModel.from_pretrained(src, subfolder="unet", **low_mem))
        stages.append(export_unet(key, load, cond, ctx))
        free_memory()
    schedulers = {
        "stage1": load_scheduler_config(stage1_src, "scheduler"),
        "stage2": load_scheduler_config(stage2_src, "scheduler"),
    }
    noising = load_scheduler_config(stage2_src, "image_noising_scheduler")
    write_manifest(
        out,
        name=name or f"{Path(stage1_src).name}+{Path(stage2_src).name}-{dtype}",
        description=f"exported from {stage1_src} and {stage2_src} ({dtype})",
        dtype=dtype,
        text=text,
        stages=stages,
        schedulers=schedulers,
        stage2_noising=noising,
    )
    (out / "versions.json").write_text(json.dumps({"seed": seed, **versions()}, indent=2) + "\n")
    if not check:
        common.warn_skip_check()
    print(f"wrote {out}")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--tiny", metavar="OUT_DIR", help="write seeded random tiny IF-architecture models")
    g.add_argument("--from-pretrained", nargs=2, metavar=("STAGE1_DIR_OR_ID", "OUT_DIR"),
                   help="export real IF weights (diffusers layout: unet/, text_encoder/, scheduler/)")
    g.add_argument("--save-tiny-diffusers", metavar="OUT_DIR",
                   help="write the tiny models in diffusers' layout (to test --from-pretrained)")
    p.add_argument("--stage2", default="DeepFloyd/IF-II-L-v1.0", help="stage-II directory or hub id")
    p.add_argument("--text-encoder", default=None,
                   help="T5 encoder directory or id (default: STAGE1/text_encoder)")
    p.add_argument("--skip-text-encoder", action="store_true",
                   help="do not export T5 (embeddings then come from `stylize embed` caches made elsewhere)")
    p.add_argument("--dtype", choices=["fp16", "fp32"], default="fp16",
                   help="fp16: the GPU profile (IF's own precision); fp32: the CPU profile -- twice the file size, "
                        "but ONNX Runtime's CPU provider then runs the weights as stored instead of keeping fp32 "
                        "cast copies of them (docs/models.md, runtime memory)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--external-data", choices=["auto", "always"], default="auto",
                   help="auto: ONNX external data only when a model exceeds 2 GB; always: for every model")
    p.add_argument("--name", default=None, help="model identity written to the manifest (embedding cache key)")
    p.add_argument("--skip-check", action="store_true",
                   help="do NOT compare the exports with PyTorch (prints a loud warning; the check takes minutes)")
    a = p.parse_args(argv)
    os.environ.setdefault("HF_HUB_DISABLE_TELEMETRY", "1")
    if a.tiny:
        run_tiny(Path(a.tiny), a.seed)
    elif a.save_tiny_diffusers:
        save_tiny_diffusers(Path(a.save_tiny_diffusers), a.seed)
    else:
        src, out = a.from_pretrained
        run_pretrained(src, Path(out), a.dtype, a.stage2, a.text_encoder, a.seed, a.skip_text_encoder, a.name,
                       a.external_data, check=not a.skip_check)


if __name__ == "__main__":
    main()
