"""Helpers shared by the ONNX exporters (export_if_onnx.py, export_clip_onnx.py).

Everything here is plain Python + NumPy at import time; torch, onnx and onnxruntime are imported inside
the functions that need them, so ``--help`` works without them.
"""

from __future__ import annotations

import hashlib
import importlib
import sys
from pathlib import Path

import numpy as np

SCRIPT_DIR = Path(__file__).resolve().parent
REPO_ROOT = SCRIPT_DIR.parent
ASSETS = REPO_ROOT / "crates" / "diffusion-onnx" / "assets"


def external_files(onnx_path: Path) -> list[str]:
    """The external-data files an ONNX model references (sorted, without duplicates)."""
    import onnx

    model = onnx.load(str(onnx_path), load_external_data=False)
    files: set[str] = set()
    for t in model.graph.initializer:
        if t.data_location == onnx.TensorProto.EXTERNAL:
            for kv in t.external_data:
                if kv.key == "location":
                    files.add(kv.value)
    return sorted(files)


def strip_debug_info(path: Path):
    """Drop the exporter's per-node stack traces and metadata (more than half of a tiny model's bytes).
    Weights are untouched; external-data references are kept as they are."""
    import onnx

    model = onnx.load(str(path), load_external_data=False)

    def strip_graph(g):
        g.doc_string = ""
        for node in g.node:
            node.doc_string = ""
            del node.metadata_props[:]
            for attr in node.attribute:
                if attr.type == onnx.AttributeProto.GRAPH:
                    strip_graph(attr.g)
                elif attr.type == onnx.AttributeProto.GRAPHS:
                    for sub in attr.graphs:
                        strip_graph(sub)
        for vi in list(g.value_info):
            del vi.metadata_props[:]
        for t in g.initializer:
            del t.metadata_props[:]

    strip_graph(model.graph)
    del model.metadata_props[:]
    onnx.save(model, str(path))


def export_module(module, args: tuple, names_in: list[str], name_out: str, path: Path, dynamic: dict, big: bool):
    """torch.onnx.export (dynamo, opset 18) of ``module`` on ``args``; ``dynamic`` maps an input name to
    its dynamic axes. ``big`` keeps the weights in an external-data file next to the model; otherwise
    the empty external-data file the dynamo exporter may leave is removed (and a small model that does
    reference external data is an error). The debug info is stripped."""
    import torch

    dyn = {}
    for name, axes in dynamic.items():
        dyn[name] = {ax: torch.export.Dim.DYNAMIC for ax in axes}
    with torch.no_grad():
        torch.onnx.export(
            module,
            args,
            str(path),
            input_names=names_in,
            output_names=[name_out],
            dynamic_shapes=dyn,
            dynamo=True,
            external_data=big,
            opset_version=18,
        )
    strip_debug_info(path)
    # The dynamo exporter may leave an empty external-data file next to a small model: drop it.
    data = path.with_name(path.name + ".data")
    if not big and data.exists():
        if external_files(path):
            raise RuntimeError(f"{path} references external data although it is small")
        data.unlink()


def check_close(got: np.ndarray, ref: np.ndarray, atol: float, rtol: float, label: str):
    """Prints the comparison and exits with an error when ``got`` is not finite or differs from ``ref``
    by more than ``atol + rtol * max|ref|`` anywhere."""
    got = np.asarray(got, dtype=np.float32)
    err = float(np.max(np.abs(got - ref)))
    scale = float(np.max(np.abs(ref)))
    tol = atol + rtol * scale
    print(f"[verify] {label}: max |onnx - torch| = {err:.3e} (max |torch| = {scale:.3e}, tolerance {tol:.3e})")
    if not np.isfinite(got).all() or err > tol:
        raise SystemExit(f"error: {label} disagrees with PyTorch beyond tolerance")


def reference_device() -> str:
    """Where the PyTorch reference of the check runs: CUDA when torch sees a GPU, else the CPU."""
    import torch

    return "cuda" if torch.cuda.is_available() else "cpu"


class Fp32Weights:
    """Context manager: ``module`` computes in fp32 although its weights stay in their stored dtype.

    Each submodule that owns floating-point parameters or buffers gets them cast to fp32 just before
    its ``forward`` and restored right after, so only one layer's fp32 copy exists at a time. Upcasting
    the whole module instead (``module.float()``) needs the fp32 copy of every weight at once -- twice
    an fp16 model, beside the fp16 pages still mapped from the checkpoint: 7.7 GiB for a 2.5 GB
    IF-II-L-size UNet, against 2.5 GiB this way (measured, docs/models.md)."""

    def __init__(self, module):
        self.module = module
        self.handles = []

    @staticmethod
    def _own_tensors(m):
        return [(n, t) for n, t in list(m.named_parameters(recurse=False)) + list(m.named_buffers(recurse=False))
                if t is not None and t.is_floating_point() and t.dtype != __import__("torch").float32]

    def __enter__(self):
        import torch

        saved = {}

        def widen(x):
            return x.float() if isinstance(x, torch.Tensor) and x.is_floating_point() else x

        def pre(m, args, kwargs):
            own = self._own_tensors(m)
            if own:
                saved[id(m)] = [(t, t.data) for _, t in own]
                for _, t in own:
                    t.data = t.data.float()
            # Inputs too: a parent may have cast its activations to this layer's (stored) weight dtype,
            # as transformers' T5 feed-forward does before `wo`.
            return tuple(widen(a) for a in args), {k: widen(v) for k, v in kwargs.items()}

        def post(m, _args, _out):
            for t, data in saved.pop(id(m), []):
                t.data = data

        for m in self.module.modules():
            if self._own_tensors(m):
                self.handles.append(m.register_forward_pre_hook(pre, with_kwargs=True))
                self.handles.append(m.register_forward_hook(post))
        return self.module

    def __exit__(self, *exc):
        for h in self.handles:
            h.remove()
        self.handles.clear()
        return False


def torch_reference(module, feeds: dict[str, np.ndarray]) -> np.ndarray:
    """``module`` on ``feeds`` (in the module's argument order) computed in **fp32**, as f32 NumPy.

    PyTorch's fp16 convolutions on the CPU run at ~1 GFLOP/s, which made the check of a real-size UNet
    take most of an hour; fp32 runs ~50x faster and is the more accurate reference anyway. Half-precision
    weights are upcast one layer at a time (:class:`Fp32Weights`), so the reference needs about the
    model's own memory, not twice it; the module is left as it was. Float inputs are widened to f32
    (their values are those the ONNX graph sees). Runs on CUDA when available (module and inputs are
    moved there)."""
    import torch

    device = reference_device()
    if device != "cpu":
        module.to(device)
    args = []
    for v in feeds.values():
        t = torch.from_numpy(np.ascontiguousarray(v))
        if t.is_floating_point():
            t = t.float()
        args.append(t.to(device))
    with torch.no_grad(), Fp32Weights(module) as m:
        out = m(*args)
    return out.float().cpu().numpy()


def onnx_run(path: Path, feeds: dict[str, np.ndarray]) -> np.ndarray:
    """The ONNX model at ``path`` on ``feeds`` in ONNX Runtime (CPU), first output as f32.

    The session keeps memory low: graph optimizations off -- ONNX Runtime then maps the external
    weights from the file and runs the fp16->fp32 casts of the CPU provider per call, instead of
    keeping an fp32 copy of every fp16 weight (a 2.5 GB fp16 UNet: 3.5 GiB peak instead of 8.8 GiB;
    the unoptimized graph is also the more literal one to check) --, no CPU memory arena, no memory
    pattern, no weight pre-packing."""
    import onnxruntime as ort

    so = ort.SessionOptions()
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_DISABLE_ALL
    so.enable_cpu_mem_arena = False
    so.enable_mem_pattern = False
    so.add_session_config_entry("session.disable_prepacking", "1")
    sess = ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])
    got = sess.run(None, feeds)[0]
    del sess
    return np.asarray(got, dtype=np.float32)


def verify(path: Path, module, feeds: dict[str, np.ndarray], atol: float, rtol: float, label: str) -> np.ndarray:
    """Runs ``module`` (PyTorch, computed in fp32 -- see :func:`torch_reference`) and the ONNX model at ``path`` (ONNX Runtime, CPU) on ``feeds`` (in the module's
    argument order), checks them with :func:`check_close` and returns the PyTorch output."""
    ref = torch_reference(module, feeds)
    got = onnx_run(path, feeds)
    check_close(got, ref, atol, rtol, label)
    return ref


SKIP_CHECK_WARNING = """
################################################################################################
#  WARNING: --skip-check: the exported ONNX models were NOT compared with PyTorch.             #
#  A wrong graph (a broken op conversion, wrong weights, a wrong output scaling) would go      #
#  unnoticed and silently ruin every stylization that uses it. Rerun without --skip-check       #
#  (the check runs at a small size in fp32: minutes, not hours) before trusting this export.   #
################################################################################################
"""


def warn_skip_check():
    """The loud warning ``--skip-check`` prints (to stderr, before and after the export)."""
    print(SKIP_CHECK_WARNING, file=sys.stderr, flush=True)


def release_weights(module):
    """Frees the storage of every parameter and buffer of ``module`` (each becomes an empty tensor of its
    dtype), so the weights are gone even while something still references the module's tensors.

    ``del module`` is not enough after ``torch.onnx.export``: onnxscript's module-level rewrite rules keep
    their last pattern match, whose values reference the exported graph, whose initializers wrap the
    module's parameters, so the weights stayed resident while ONNX Runtime's check mapped the exported
    ones beside them. Not enough on its own when the weights are views of a memory-mapped checkpoint
    (``low_cpu_mem_usage``): torch itself keeps a few of those tensors, and with them the whole mapping
    (export_if_onnx.in_child handles that). The module is unusable afterwards."""
    import torch

    with torch.no_grad():
        for t in list(module.parameters()) + list(module.buffers()):
            t.data = torch.empty(0, dtype=t.dtype, device=t.device)


def rss_now_gib() -> tuple[float, float]:
    """(anonymous, file-backed) resident memory of this process now, GiB (Linux; (0, 0) elsewhere)."""
    try:
        fields = dict(line.split(":", 1) for line in Path("/proc/self/status").read_text().splitlines() if ":" in line)
        return int(fields["RssAnon"].split()[0]) / 2**20, int(fields["RssFile"].split()[0]) / 2**20
    except (OSError, KeyError, ValueError):
        return 0.0, 0.0


class MemoryPhases:
    """Peak resident memory per phase of an export, sampled by a background thread every ``interval``
    seconds (``ru_maxrss`` only gives the peak of the whole process). ``phase(name)`` starts a phase;
    ``summary()`` lists each phase's peak with its anonymous / file-backed split at that moment.

    File-backed pages (the checkpoint, the written or mapped ONNX weights) count in RSS as the kernel
    reports it, although it can drop them under pressure; the split says how much of a peak they are."""

    def __init__(self, interval: float = 0.05):
        import threading

        self.interval = interval
        self.current = "start"
        self.peaks: dict[str, tuple[float, float, float]] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _sample(self):
        anon, file = rss_now_gib()
        with self._lock:
            best = self.peaks.get(self.current)
            if best is None or anon + file > best[0]:
                self.peaks[self.current] = (anon + file, anon, file)

    def _run(self):
        while not self._stop.wait(self.interval):
            self._sample()

    def phase(self, name: str):
        self._sample()
        with self._lock:
            self.current = name
        self._sample()

    def summary(self) -> str:
        self._sample()
        with self._lock:
            return "; ".join(f"{n} {t:.2f} (anon {a:.2f}, file {f:.2f})" for n, (t, a, f) in self.peaks.items())

    def stop(self):
        self._stop.set()
        self._thread.join()


def peak_rss_gib() -> float:
    """This process's peak resident set size so far (GiB; Linux ``ru_maxrss`` is in KiB)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / (1 << 20)


def sha256(path: Path) -> str:
    """Lower-case hex SHA-256 of a file."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def versions(modules: dict[str, str]) -> dict:
    """``{label: version}`` for each ``label: import name`` in ``modules``, plus the Python version (the
    ``versions.json`` an export writes)."""
    out = {label: importlib.import_module(name).__version__ for label, name in modules.items()}
    out["python"] = sys.version.split()[0]
    return out
