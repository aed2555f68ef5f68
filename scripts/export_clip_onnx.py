#!/usr/bin/env python3
"""Export a CLIP model (image and text encoders) to ONNX for `diffusion_onnx::clip` (`stylize eval --clip`).

Two modes, one output layout (``manifest.toml`` + two ``.onnx`` files, see docs/models.md, "CLIP"):

  --tiny OUT_DIR
      A seeded, randomly initialised transformers ``CLIPModel`` with ViT-B/16's structure scaled down
      (patch 16, 32 px images, 1 layer, widths 8/16, projection 8) and the full 49,408-token vocabulary
      so the real CLIP tokenizer works; plus PyTorch reference inputs/outputs under ``reference/``.
      Used as the test fixture fixtures/models/tiny-clip. No weights are downloaded.

  --from-pretrained DIR_OR_ID OUT_DIR
      A real CLIP for users who have it, e.g. ``openai/clip-vit-base-patch16`` (the paper's metric model)
      or a local directory in transformers' layout. The image size, mean/std and context length are read
      from the model's config and ``preprocessor_config.json``.

The graphs:
  image_encoder.onnx: ``pixel_values`` f32 [B, 3, S, S] (already normalized with mean/std) →
                      ``image_embeds`` f32 [B, D]: the visual projection of the pooled output,
                      **not** L2-normalized (``CLIPModel.get_image_features``).
  text_encoder.onnx:  ``input_ids`` int64 [B, 77] → ``text_embeds`` f32 [B, D]: the text projection of
                      the hidden state at the first end-of-text token, **not** L2-normalized
                      (``CLIPModel.get_text_features``). No attention mask: CLIP's text transformer is
                      causal, so tokens after the first end-of-text token cannot change it. Ids are
                      ``<|startoftext|>`` (49406), the BPE tokens (at most 75), ``<|endoftext|>`` (49407),
                      then padding with 49407 (Hugging Face's CLIP tokenizer convention). Pooling takes the
                      first 49407: with OpenAI's config (``eos_token_id = 2``) transformers takes the
                      argmax of the ids, which is that position since 49407 is the largest id.

Every graph is run in ONNX Runtime and in PyTorch on the same inputs; the script fails when the maximum
absolute difference exceeds 1e-4 + 1e-4 * max|torch output|. The manifest records each file's sha256.

Needs: torch (CPU is enough), transformers, onnx, onnxscript, onnxruntime, numpy, tokenizers, pillow.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

# Shared with the IF exporter (this directory is on sys.path when a script here runs).
import onnx_export_common as common
from onnx_export_common import sha256

TOKENIZER_JSON = common.ASSETS / "clip_tokenizer.json"
FORMAT_VERSION = 1
CONTEXT_LENGTH = 77
BOS_ID = 49406
EOS_ID = 49407
PAD_ID = 49407
VOCAB_SIZE = 49408
# OpenAI CLIP's image normalization (CLIPImageProcessor's defaults).
CLIP_MEAN = [0.48145466, 0.4578275, 0.40821073]
CLIP_STD = [0.26862954, 0.26130258, 0.27577711]
ATOL, RTOL = 1e-4, 1e-4

# ViT-B/16's structure, scaled down. The token embedding (49,408 × 8 f32 = 1.6 MB) dominates the size.
TINY_TEXT = dict(
    vocab_size=VOCAB_SIZE,
    hidden_size=8,
    intermediate_size=16,
    num_hidden_layers=1,
    num_attention_heads=2,
    max_position_embeddings=CONTEXT_LENGTH,
    hidden_act="quick_gelu",
    # OpenAI's configs say 2 (a legacy value); transformers then pools at argmax(input_ids).
    bos_token_id=0,
    eos_token_id=2,
    pad_token_id=1,
)
TINY_VISION = dict(
    image_size=32,
    patch_size=16,
    num_channels=3,
    hidden_size=16,
    intermediate_size=32,
    num_hidden_layers=1,
    num_attention_heads=2,
    hidden_act="quick_gelu",
)
TINY_PROJECTION = 8

PROMPTS = [
    "a photo of a cat",
    "  A Wooden CHAIR,   Ornate!  ",
    "a very ornate wooden chair " * 20,  # truncated to 75 BPE tokens
    "",
]


def tokenize(prompts: list[str]) -> np.ndarray:
    """CLIP tokenization as the Rust side does it: the tokenizer JSON's normalizer (NFC, runs of white
    space → one space, lower case) and BPE without special tokens, content truncated to 75 tokens, then
    [49406] + content + [49407], padded with 49407 to 77."""
    from tokenizers import Tokenizer

    tok = Tokenizer.from_file(str(TOKENIZER_JSON))
    ids = np.full((len(prompts), CONTEXT_LENGTH), PAD_ID, dtype=np.int64)
    for i, p in enumerate(prompts):
        enc = list(tok.encode(p, add_special_tokens=False).ids)
        enc = [BOS_ID] + enc[: CONTEXT_LENGTH - 2] + [EOS_ID]
        ids[i, : len(enc)] = enc
    return ids


def pil_bicubic_resize(images: np.ndarray, size: int) -> np.ndarray:
    """[N, H, W, 3] f32 → [N, size, size, 3] with PIL's BICUBIC filter on 32-bit float planes (mode "F"):
    the same filter CLIPImageProcessor uses (a = -0.5, support widened by the scale factor when
    reducing), without 8-bit quantization."""
    from PIL import Image

    out = np.zeros((images.shape[0], size, size, 3), dtype=np.float32)
    for n in range(images.shape[0]):
        for c in range(3):
            plane = Image.fromarray(np.ascontiguousarray(images[n, :, :, c], dtype=np.float32), mode="F")
            out[n, :, :, c] = np.asarray(plane.resize((size, size), Image.BICUBIC), dtype=np.float32)
    return out


def preprocess(images: np.ndarray, size: int, mean: list[float], std: list[float]) -> np.ndarray:
    """Square [N, H, W, 3] images in [0, 1] → pixel_values [N, 3, size, size]: bicubic resize (a no-op
    for size == H), then (x - mean) / std per channel. For square images CLIPImageProcessor's
    shortest-side resize + centre crop is exactly this resize."""
    x = images if images.shape[1] == size else pil_bicubic_resize(images, size)
    x = (x - np.asarray(mean, np.float32)) / np.asarray(std, np.float32)
    return np.ascontiguousarray(x.transpose(0, 3, 1, 2), dtype=np.float32)


def make_wrappers():
    import torch

    class ImageEncoder(torch.nn.Module):
        def __init__(self, clip):
            super().__init__()
            self.vision = clip.vision_model
            self.proj = clip.visual_projection

        def forward(self, pixel_values):
            pooled = self.vision(pixel_values=pixel_values).pooler_output
            return self.proj(pooled)

    class TextEncoder(torch.nn.Module):
        def __init__(self, clip):
            super().__init__()
            self.text = clip.text_model
            self.proj = clip.text_projection

        def forward(self, input_ids):
            pooled = self.text(input_ids=input_ids).pooler_output
            return self.proj(pooled)

    return ImageEncoder, TextEncoder


def export_module(module, arg, name_in: str, name_out: str, path: Path):
    common.export_module(module, (arg,), [name_in], name_out, path, {name_in: [0]}, big=False)


def verify(path: Path, module, name_in: str, x: np.ndarray, label: str) -> np.ndarray:
    return common.verify(path, module, {name_in: x}, ATOL, RTOL, label)


def reference_images(rng: np.random.Generator, n: int, side: int) -> np.ndarray:
    """Smooth random RGB images in [0, 1], [n, side, side, 3] (row, column, channel)."""
    yy, xx = np.meshgrid(np.linspace(0, 1, side), np.linspace(0, 1, side), indexing="ij")
    out = np.zeros((n, side, side, 3), dtype=np.float32)
    for i in range(n):
        for c in range(3):
            a, b, p, q = rng.uniform(0.5, 4.0, 4)
            v = 0.5 + 0.25 * np.sin(a * np.pi * xx + p) * np.cos(b * np.pi * yy + q)
            out[i, :, :, c] = v + 0.1 * rng.standard_normal((side, side))
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def export_clip(clip, out: Path, name: str, description: str, size: int, mean, std, seed: int, reference: bool):
    import torch

    out.mkdir(parents=True, exist_ok=True)
    ImageEncoder, TextEncoder = make_wrappers()
    image_enc = ImageEncoder(clip).eval()
    text_enc = TextEncoder(clip).eval()
    dim = int(clip.config.projection_dim)
    rng = np.random.default_rng(seed)

    ids = tokenize(PROMPTS)
    text_path = out / "text_encoder.onnx"
    export_module(text_enc, torch.from_numpy(ids), "input_ids", "text_embeds", text_path)
    text_embeds = verify(text_path, text_enc, "input_ids", ids, "text_encoder")
    # The padding convention must not matter (causal attention, pooling at the first 49407): OpenAI's
    # own tokenizer pads with 0; that must give the same embeddings as the 49407 padding used here.
    zero_pad = ids.copy()
    for i in range(len(ids)):
        zero_pad[i, int(np.argmax(ids[i] == EOS_ID)) + 1 :] = 0
    with torch.no_grad():
        alt = text_enc(torch.from_numpy(zero_pad)).numpy()
    pad_err = float(np.max(np.abs(alt - text_embeds)))
    print(f"[verify] text_encoder: 0-padding vs 49407-padding max difference {pad_err:.3e}")
    if pad_err > 1e-5:
        raise SystemExit("error: the text embedding depends on the padding; pooling is not at the first end-of-text")

    # Reference images: 48 px (so the Rust resize is exercised) and the model's size.
    big = reference_images(rng, 2, 48 if size < 48 else size + 16)
    exact = reference_images(rng, 1, size)
    pixel_big = preprocess(big, size, mean, std)
    pixel_exact = preprocess(exact, size, mean, std)
    pixel_values = np.concatenate([pixel_big, pixel_exact], axis=0)
    image_path = out / "image_encoder.onnx"
    export_module(image_enc, torch.from_numpy(pixel_values), "pixel_values", "image_embeds", image_path)
    image_embeds = verify(image_path, image_enc, "pixel_values", pixel_values, "image_encoder")

    if reference:
        ref = out / "reference"
        ref.mkdir(exist_ok=True)
        np.save(ref / "input_ids.npy", ids)
        np.save(ref / "text_embeds.npy", text_embeds.astype(np.float32))
        np.save(ref / "images_resized.npy", big)
        np.save(ref / "images_exact.npy", exact)
        np.save(ref / "pixel_values.npy", pixel_values)
        np.save(ref / "image_embeds.npy", image_embeds.astype(np.float32))
        (ref / "prompts.json").write_text(json.dumps(PROMPTS, indent=2) + "\n")

    lines = [
        "# diffusion-onnx CLIP model directory manifest (see docs/models.md, \"CLIP\")",
        f"format_version = {FORMAT_VERSION}",
        f"name = {json.dumps(name)}",
        f"description = {json.dumps(description)}",
        f"embedding_dim = {dim}",
        "",
        "[image_encoder]",
        f'file = "{image_path.name}"',
        f'sha256 = "{sha256(image_path)}"',
        'input = "pixel_values"',
        'output = "image_embeds"',
        f"image_size = {size}",
        f"mean = {json.dumps([float(m) for m in mean])}",
        f"std = {json.dumps([float(s) for s in std])}",
        "",
        "[text_encoder]",
        f'file = "{text_path.name}"',
        f'sha256 = "{sha256(text_path)}"',
        'input_ids = "input_ids"',
        'output = "text_embeds"',
        'tokenizer = "builtin:clip"',
        f"context_length = {CONTEXT_LENGTH}",
        f"bos_id = {BOS_ID}",
        f"eos_id = {EOS_ID}",
        f"pad_id = {PAD_ID}",
        "",
    ]
    (out / "manifest.toml").write_text("\n".join(lines))
    (out / "versions.json").write_text(json.dumps({"seed": seed, **versions()}, indent=2) + "\n")
    total = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    print(f"wrote {out} ({total / 1e6:.2f} MB)")


def versions() -> dict:
    return common.versions({
        "torch": "torch",
        "transformers": "transformers",
        "onnx": "onnx",
        "onnxscript": "onnxscript",
        "onnxruntime": "onnxruntime",
        "pillow": "PIL",
    })


def build_tiny(seed: int):
    import torch
    from transformers import CLIPConfig, CLIPModel

    torch.manual_seed(seed)
    cfg = CLIPConfig(text_config=TINY_TEXT, vision_config=TINY_VISION, projection_dim=TINY_PROJECTION)
    return CLIPModel(cfg).eval()


def run_tiny(out: Path, seed: int):
    clip = build_tiny(seed)
    export_clip(
        clip,
        out,
        name=f"tiny-clip-seed{seed}",
        description="Randomly initialised tiny CLIP with ViT-B/16's structure (test fixture, not a real model)",
        size=TINY_VISION["image_size"],
        mean=CLIP_MEAN,
        std=CLIP_STD,
        seed=seed,
        reference=True,
    )


def run_pretrained(src: str, out: Path, name: str | None, seed: int):
    from transformers import CLIPModel

    clip = CLIPModel.from_pretrained(src).float().eval()
    if clip.text_model.config.max_position_embeddings != CONTEXT_LENGTH:
        raise SystemExit(f"error: the text model has {clip.text_model.config.max_position_embeddings} positions, "
                         f"the Rust side uses {CONTEXT_LENGTH}")
    if clip.text_model.config.vocab_size != VOCAB_SIZE:
        raise SystemExit("error: not the OpenAI CLIP vocabulary (49,408 tokens); the builtin tokenizer would not match")
    size = int(clip.config.vision_config.image_size)
    mean, std = CLIP_MEAN, CLIP_STD
    pre = Path(src) / "preprocessor_config.json"
    if pre.is_file():
        p = json.loads(pre.read_text())
        mean, std = p.get("image_mean", mean), p.get("image_std", std)
        crop = p.get("crop_size", size)
        crop = crop.get("height", size) if isinstance(crop, dict) else crop
        if int(crop) != size:
            raise SystemExit(f"error: preprocessor crop size {crop} differs from the model's image size {size}")
    export_clip(
        clip,
        out,
        name=name or Path(src).name,
        description=f"CLIP exported from {src}",
        size=size,
        mean=mean,
        std=std,
        seed=seed,
        reference=False,
    )


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--tiny", metavar="OUT_DIR", help="write a seeded random tiny CLIP (test fixture)")
    g.add_argument("--from-pretrained", nargs=2, metavar=("DIR_OR_ID", "OUT_DIR"),
                   help="export a real CLIP in transformers' layout (e.g. openai/clip-vit-base-patch16)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--name", default=None, help="model name written to the manifest")
    a = p.parse_args(argv)
    os.environ.setdefault("HF_HUB_DISABLE_TELEMETRY", "1")
    if a.tiny:
        run_tiny(Path(a.tiny), a.seed)
    else:
        src, out = a.from_pretrained
        run_pretrained(src, Path(out), a.name, a.seed)


if __name__ == "__main__":
    main()
