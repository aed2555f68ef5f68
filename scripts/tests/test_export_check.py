"""The exporter's check (fp32 PyTorch reference at a small size vs ONNX Runtime) accepts a correct
export and catches broken ones. Needs torch, diffusers, onnx, onnxscript, onnxruntime (the export
environment, scripts/requirements-export.txt); skipped cleanly where they are missing (the CI venv).

Run: `python -m pytest scripts/tests/test_export_check.py` with the export environment's Python.
"""

import copy
import sys
from pathlib import Path

import numpy as np
import pytest

for mod in ("torch", "diffusers", "transformers", "onnx", "onnxscript", "onnxruntime", "tokenizers"):
    pytest.importorskip(mod)

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import export_if_onnx as exp  # noqa: E402
import onnx_export_common as common  # noqa: E402


@pytest.fixture(scope="module")
def tiny_stage1_fp16(tmp_path_factory):
    """The tiny stage-I UNet exported in fp16 (external data, as a real-size model), with its check
    inputs and the fp32 PyTorch reference of the fp16 weights."""
    import torch

    _, stage1, _ = exp.build_tiny(0)
    stage1 = stage1.to(torch.float16)
    out = tmp_path_factory.mktemp("export")
    ctx = exp.ExportContext(out, "fp16", seed=0, big=True, save_reference=False, check=True)
    # The export frees the weights of the module it is given: it gets a copy.
    spec = exp.export_unet("stage1", lambda: copy.deepcopy(stage1),
                           np.random.default_rng(1).standard_normal((2, 77, 8)), ctx)
    path = out / spec.file
    assert spec.external == [path.name + ".data"], "the export must use external data"
    # The same feeds again, for the tests below (export_unet's are drawn from ctx.rng(seed 0)).
    rng = np.random.default_rng(0)
    feeds = {
        "sample": rng.standard_normal((2, 3, 32, 32)).astype(np.float16),
        "timestep": np.array([20, 980], dtype=np.int64),
        "encoder_hidden_states": np.random.default_rng(1).standard_normal((2, 77, 8)).astype(np.float16),
    }
    ref = common.torch_reference(exp.make_wrappers()[0](stage1).eval(), feeds)
    return path, feeds, ref


def perturb_initializer(path: Path, out: Path, pick, change):
    """Copies the ONNX model at ``path`` (external data included) to ``out`` with ``change`` applied to
    the first float initializer whose name satisfies ``pick``; returns that name."""
    import onnx
    from onnx import numpy_helper

    model = onnx.load(str(path), load_external_data=True)
    for t in model.graph.initializer:
        if t.data_type in (onnx.TensorProto.FLOAT16, onnx.TensorProto.FLOAT) and pick(t.name):
            arr = numpy_helper.to_array(t).copy()
            change(arr)
            t.CopyFrom(numpy_helper.from_array(arr, t.name))
            onnx.save(model, str(out))
            return t.name
    raise AssertionError("no initializer matched")


def test_correct_fp16_export_passes_the_check(tiny_stage1_fp16, capsys):
    path, feeds, ref = tiny_stage1_fp16
    exp.check(path, ref, feeds, "fp16", "correct")
    assert "[verify] correct" in capsys.readouterr().out


def test_one_perturbed_weight_fails_the_check(tiny_stage1_fp16, tmp_path):
    path, feeds, ref = tiny_stage1_fp16

    def bump_one(arr):
        flat = arr.reshape(-1)
        flat[0] += arr.dtype.type(0.5)  # one weight of the output convolution

    name = perturb_initializer(path, tmp_path / "broken.onnx", lambda n: "conv_out" in n and "weight" in n, bump_one)
    assert "conv_out" in name
    with pytest.raises(SystemExit, match="beyond tolerance"):
        exp.check(tmp_path / "broken.onnx", ref, feeds, "fp16", "one weight off")


def test_wrong_output_scaling_fails_the_check(tiny_stage1_fp16, tmp_path):
    """A graph whose output is 10 % too large (e.g. a lost ``resnet_out_scale_factor``-like constant)."""
    path, feeds, ref = tiny_stage1_fp16

    def scale(arr):
        arr *= arr.dtype.type(1.1)

    perturb_initializer(path, tmp_path / "scaled.onnx", lambda n: "conv_out" in n, scale)
    with pytest.raises(SystemExit, match="beyond tolerance"):
        exp.check(tmp_path / "scaled.onnx", ref, feeds, "fp16", "output x1.1")


def test_torch_reference_computes_in_fp32_and_leaves_the_module_in_fp16():
    """The reference of an fp16 layer equals the fp32 computation on the fp16-rounded weights (not an
    fp16 computation), and the module keeps its fp16 weights (one layer is upcast at a time)."""
    import torch

    torch.manual_seed(0)
    seq = torch.nn.Sequential(torch.nn.Linear(64, 64), torch.nn.GELU(), torch.nn.Linear(64, 3)).to(torch.float16)
    x = np.random.default_rng(0).standard_normal((2, 64)).astype(np.float16)
    y = common.torch_reference(seq, {"x": x})
    assert y.dtype == np.float32 and y.shape == (2, 3)
    assert all(p.dtype == torch.float16 for p in seq.parameters()), "weights stay fp16"
    assert not seq[0]._forward_pre_hooks, "hooks removed"
    fp32 = [m.float() if hasattr(m, "weight") else m for m in [torch.nn.Linear(64, 64), torch.nn.GELU(), torch.nn.Linear(64, 3)]]
    exact = torch.nn.Sequential(*fp32)
    exact.load_state_dict({k: v.float() for k, v in seq.state_dict().items()})
    with torch.no_grad():
        want = exact(torch.from_numpy(x).float()).numpy()
    np.testing.assert_allclose(y, want, rtol=1e-6, atol=1e-6)


def test_skip_check_warning_is_loud(capsys):
    common.warn_skip_check()
    err = capsys.readouterr().err
    assert "WARNING" in err and "NOT compared" in err


def test_export_frees_the_weights_before_the_check(tmp_path):
    """The exported module's weights are freed before ONNX Runtime maps the export (they stayed resident
    through onnxscript's rewrite rules and doubled the check's memory), and the per-phase memory report
    names each phase."""
    import gc
    import weakref

    import torch

    _, stage1, _ = exp.build_tiny(0)
    weight = stage1.conv_out.weight
    storage = weakref.ref(weight.untyped_storage())
    ctx = exp.ExportContext(tmp_path, "fp32", seed=0, big=True, save_reference=False, check=True,
                            memory=common.MemoryPhases())
    exp.export_unet("stage1", lambda: stage1, np.random.default_rng(1).standard_normal((2, 77, 8)), ctx)
    gc.collect()
    assert weight.numel() == 0 and weight.dtype == torch.float32, "the parameter's data is released"
    assert storage() is None, "nothing keeps the old weight storage alive"
    summary = ctx.memory.summary()
    ctx.memory.stop()
    for phase in ("stage1 load", "stage1 export", "stage1 reference", "stage1 check"):
        assert phase in summary


def test_in_child_runs_in_another_process_and_carries_state_back(tmp_path):
    """With ``isolate`` the model side runs in a forked child: its result, its RNG draws and its
    external-data decision come back; a failure there is an error here, not a silent empty result."""
    import os

    ctx = exp.ExportContext(tmp_path, "fp16", seed=3, big=False, save_reference=False, isolate=True,
                            memory=common.MemoryPhases())

    def side(c):
        c.phase("child work")
        c.big = True
        return os.getpid(), c.rng.standard_normal(3)

    pid, drawn = exp.in_child(ctx, side, ctx)
    assert pid != os.getpid()
    assert ctx.big, "the child's external-data decision is carried back"
    expected = np.random.default_rng(3)
    np.testing.assert_array_equal(drawn, expected.standard_normal(3))
    np.testing.assert_array_equal(ctx.rng.standard_normal(2), expected.standard_normal(2))
    assert "child work [child]" in ctx.memory.summary()
    ctx.memory.stop()

    def boom(_c):
        raise ValueError("broken model")

    with pytest.raises(SystemExit, match="broken model"):
        exp.in_child(ctx, boom, ctx)
