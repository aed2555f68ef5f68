"""The NumPy API of darap: agreement with the golden data and the Rust CLI, exact gradients,
array layouts and dtypes, and the errors raised for bad inputs."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import darap

from conftest import GOLDEN, GOLDEN_CASES, REPO, read_obj


def sphere_layer(level: int = 2, **kwargs) -> darap.Darap:
    verts, faces = darap.icosphere(level)
    return darap.Darap(verts, faces, **kwargs)


def tilted_targets(layer: darap.Darap, rng: np.random.Generator, scale: float = 0.6) -> np.ndarray:
    """Rest normals plus a random perturbation, rows of varying length (only directions matter)."""
    n0 = layer.rest_normals()
    x = n0 + scale * rng.standard_normal(n0.shape)
    return x * rng.uniform(0.5, 2.0, size=(len(x), 1))


# ---------------------------------------------------------------------------------------------
# Forward: golden data and the Rust CLI


@pytest.mark.parametrize("case,lam,rule", GOLDEN_CASES)
def test_forward_matches_golden_bunny(golden_npz: Path, case: str, lam: float, rule: str) -> None:
    saved = darap.load_saved(golden_npz)
    positions = saved.apply(lam=lam, rotation_rule=rule)
    expected, expected_faces = read_obj(GOLDEN / f"{case}.obj")
    np.testing.assert_array_equal(expected_faces, saved.faces)
    err = np.abs(positions - expected).max()
    assert err <= 1e-9, f"{case}: max |Δposition| = {err:.3e}"


def find_stylize() -> Path | None:
    env = os.environ.get("DARAP_STYLIZE_BIN")
    if env:
        return Path(env)
    for profile in ("debug", "release"):
        exe = REPO / "target" / profile / "stylize"
        if exe.is_file():
            return exe
    return None


@pytest.mark.parametrize("lam,rule", [(8.0, "gis"), (40.0, "procrustes")])
def test_forward_matches_rust_cli_apply(golden_npz: Path, tmp_path: Path, lam: float, rule: str) -> None:
    exe = find_stylize()
    if exe is None:
        pytest.skip("no stylize binary in target/ (cargo build --bin stylize) and DARAP_STYLIZE_BIN unset")
    out = tmp_path / "applied.obj"
    cmd = [str(exe), "apply", str(golden_npz), "-o", str(out), "--lambda", str(lam), "--rotation-rule", rule]
    subprocess.run(cmd, check=True, capture_output=True, timeout=300)
    cli_positions, cli_faces = read_obj(out)
    positions = darap.load_saved(golden_npz).apply(lam=lam, rotation_rule=rule)
    np.testing.assert_array_equal(cli_faces, darap.load_saved(golden_npz).faces)
    # The CLI writes shortest round-trip decimals: the same f64 computation agrees to rounding.
    err = np.abs(positions - cli_positions).max()
    assert err <= 1e-12, f"max |Δposition| vs stylize apply = {err:.3e}"


def test_rest_normals_are_unit_and_outward() -> None:
    verts, faces = darap.icosphere(3)
    layer = darap.Darap(verts, faces)
    n0 = layer.rest_normals()
    assert n0.shape == verts.shape and n0.dtype == np.float64
    np.testing.assert_allclose(np.linalg.norm(n0, axis=1), 1.0, atol=1e-12)
    # On a sphere centred at the origin the outward normal is the (unit) position.
    unit = verts / np.linalg.norm(verts, axis=1, keepdims=True)
    assert (np.einsum("ij,ij->i", n0, unit) > 0.99).all()


def test_rest_normals_as_targets_give_back_the_rest_mesh_up_to_recentering() -> None:
    verts, faces = darap.icosphere(2)
    layer = darap.Darap(verts, faces, post_process="none")
    out = layer.forward(layer.rest_normals())
    # λ·a·n0·n0ᵀ only reinforces the rest frame: R = I and the closed mesh is reproduced.
    np.testing.assert_allclose(out.positions, verts, atol=1e-9)


def test_rotations_are_proper_rotations(rng: np.random.Generator) -> None:
    layer = sphere_layer(2)
    out = layer.forward(tilted_targets(layer, rng))
    r = out.rotations
    assert r.shape == (layer.num_vertices, 3, 3)
    eye = np.broadcast_to(np.eye(3), r.shape)
    np.testing.assert_allclose(r @ np.swapaxes(r, 1, 2), eye, atol=1e-10)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-10)
    assert out.lam == 8.0


# ---------------------------------------------------------------------------------------------
# Backward: golden directional derivatives and central finite differences


@pytest.mark.parametrize("case,lam,rule", GOLDEN_CASES)
def test_backward_matches_golden_directional_derivatives(golden_npz: Path, case: str, lam: float, rule: str) -> None:
    saved = darap.load_saved(golden_npz)
    layer = saved.layer(lam=lam, rotation_rule=rule)
    with np.load(GOLDEN / "bunny_vjp.npz") as vjp:
        cotangent = vjp["golden_cotangent"]
        directions = [vjp[f"direction_{k}"] for k in range(3)]
        expected = vjp[f"{case}_directional"]
    out = layer.forward(saved.targets())
    grad_x = layer.backward(out, cotangent)
    for k, d in enumerate(directions):
        analytic = float(np.sum(grad_x * d))
        rel = abs(analytic - expected[k]) / max(abs(expected[k]), 1e-12)
        assert rel < 1e-6, f"{case} direction {k}: {analytic:.12e} vs golden {expected[k]:.12e}"


def central_difference(layer: darap.Darap, x: np.ndarray, cotangent: np.ndarray, d: np.ndarray, h: float = 1e-6) -> float:
    plus = layer.forward(x + h * d).positions
    minus = layer.forward(x - h * d).positions
    return float(np.sum(cotangent * (plus - minus)) / (2 * h))


@pytest.mark.parametrize(
    "rule,lam,post",
    [("gis", 8.0, "recenter_rescale"), ("procrustes", 40.0, "recenter_rescale"), ("gis", 5.0, "none"), ("gis", 8.0, "recenter_only")],
)
def test_backward_equals_central_differences(rng: np.random.Generator, rule: str, lam: float, post: str) -> None:
    layer = sphere_layer(2, lam=lam, rotation_rule=rule, post_process=post)
    x = tilted_targets(layer, rng, scale=0.3)
    cotangent = rng.standard_normal(x.shape)
    out = layer.forward(x)
    grad_x = layer.backward(out, cotangent)
    assert grad_x.shape == x.shape and grad_x.dtype == np.float64
    for _ in range(4):
        d = rng.standard_normal(x.shape)
        fd = central_difference(layer, x, cotangent, d)
        analytic = float(np.sum(grad_x * d))
        assert abs(analytic - fd) <= 1e-6 * max(abs(fd), 1e-3), f"analytic {analytic:.10e} vs FD {fd:.10e}"


def test_full_jacobian_transpose_matches_finite_differences(rng: np.random.Generator) -> None:
    """Every entry of ∂ℓ/∂x on a 42-vertex sphere against central differences."""
    layer = sphere_layer(1)
    x = tilted_targets(layer, rng, scale=0.3)
    cotangent = rng.standard_normal(x.shape)
    grad_x = layer.backward(layer.forward(x), cotangent)
    fd = np.zeros_like(x)
    for i in range(x.shape[0]):
        for c in range(3):
            e = np.zeros_like(x)
            e[i, c] = 1.0
            fd[i, c] = central_difference(layer, x, cotangent, e)
    np.testing.assert_allclose(grad_x, fd, rtol=1e-5, atol=1e-7)


def test_backward_uses_the_lambda_of_its_forward(rng: np.random.Generator) -> None:
    layer = sphere_layer(2, lam=8.0)
    x = tilted_targets(layer, rng)
    cotangent = rng.standard_normal(x.shape)
    out8 = layer.forward(x)
    expected = layer.backward(out8, cotangent)
    layer.set_lambda(3.0)
    np.testing.assert_array_equal(layer.backward(out8, cotangent), expected)


# ---------------------------------------------------------------------------------------------
# Options: λ, masks, rotation rules


def test_set_lambda_equals_a_layer_built_with_that_lambda(rng: np.random.Generator) -> None:
    verts, faces = darap.icosphere(2)
    layer = darap.Darap(verts, faces, lam=8.0)
    x = tilted_targets(layer, rng)
    before = layer.forward(x).positions
    layer.set_lambda(5.0)
    assert layer.lam == 5.0
    after = layer.forward(x).positions
    np.testing.assert_array_equal(after, darap.Darap(verts, faces, lam=5.0).forward(x).positions)
    assert np.abs(after - before).max() > 1e-6


def test_rotation_rule_and_post_process_setters() -> None:
    layer = sphere_layer(1)
    assert (layer.rotation_rule, layer.post_process) == ("gis", "recenter_rescale")
    layer.set_rotation_rule("procrustes")
    layer.set_post_process("none")
    assert (layer.rotation_rule, layer.post_process) == ("procrustes", "none")


def test_all_false_mask_keeps_the_rest_shape_and_blocks_gradients(rng: np.random.Generator) -> None:
    verts, faces = darap.icosphere(2)
    frozen = darap.Darap(verts, faces, mask=np.zeros(len(verts), dtype=bool), post_process="none")
    x = tilted_targets(frozen, rng)
    out = frozen.forward(x)
    np.testing.assert_allclose(out.positions, verts, atol=1e-9)
    np.testing.assert_array_equal(out.rotations, np.broadcast_to(np.eye(3), out.rotations.shape))
    assert not frozen.backward(out, rng.standard_normal(x.shape)).any()


def test_mask_limits_rotation_to_the_free_region(rng: np.random.Generator) -> None:
    verts, faces = darap.icosphere(2)
    free = verts[:, 2] > 0.3
    layer = darap.Darap(verts, faces, mask=free)
    x = tilted_targets(layer, rng)
    out = layer.forward(x)
    eye = np.eye(3)
    assert np.array_equal(out.rotations[~free], np.broadcast_to(eye, (int((~free).sum()), 3, 3)))
    assert np.abs(out.rotations[free] - eye).max() > 1e-3
    grad = layer.backward(out, rng.standard_normal(x.shape))
    assert not grad[~free].any() and grad[free].any()
    # Removing the mask is the same as an all-True mask.
    layer.set_mask(None)
    unmasked = layer.forward(x).positions
    layer.set_mask(np.ones(len(verts), dtype=bool))
    np.testing.assert_array_equal(layer.forward(x).positions, unmasked)


# ---------------------------------------------------------------------------------------------
# Dtypes and memory layouts


def test_float32_fortran_and_strided_inputs_equal_float64_c_order(rng: np.random.Generator) -> None:
    verts, faces = darap.icosphere(2)
    verts = verts.astype(np.float32).astype(np.float64)  # values exactly representable in f32
    x = tilted_targets(darap.Darap(verts, faces), rng).astype(np.float32).astype(np.float64)
    reference = darap.Darap(verts, faces).forward(x).positions

    variants_verts = [verts.astype(np.float32), np.asfortranarray(verts), np.repeat(verts, 2, axis=0)[::2]]
    variants_faces = [faces.astype(np.int32), np.asfortranarray(faces), faces.astype(np.uint32), faces.astype(np.uint64)]
    variants_x = [x.astype(np.float32), np.asfortranarray(x), x[:, [0, 1, 2]]]
    for v in variants_verts:
        np.testing.assert_array_equal(darap.Darap(v, faces).forward(x).positions, reference)
    for f in variants_faces:
        np.testing.assert_array_equal(darap.Darap(verts, f).forward(x).positions, reference)
    layer = darap.Darap(verts, faces)
    strided = np.zeros((len(x), 6))
    strided[:, ::2] = x
    for xv in variants_x + [strided[:, ::2], np.ascontiguousarray(x[::-1])[::-1]]:
        np.testing.assert_array_equal(layer.forward(xv).positions, reference)


def test_outputs_are_fresh_float64_c_arrays(rng: np.random.Generator) -> None:
    layer = sphere_layer(1)
    x = tilted_targets(layer, rng)
    out = layer.forward(x)
    p = out.positions
    assert p.dtype == np.float64 and p.flags.c_contiguous and p.flags.writeable
    g = layer.backward(out, np.ones_like(x))
    # Writing into the returned positions does not change what backward computes.
    p[:] = 0.0
    np.testing.assert_array_equal(layer.backward(out, np.ones_like(x)), g)
    n0 = layer.rest_normals()
    n0[:] = 0.0
    assert np.abs(layer.rest_normals()).max() > 0.5
    assert layer.rest_positions().shape == (layer.num_vertices, 3)
    assert layer.mass().shape == (layer.num_vertices,) and (layer.mass() > 0).all()
    np.testing.assert_array_equal(layer.pins(), [0])


def test_components_are_pinned_separately() -> None:
    verts, faces = darap.icosphere(1)
    v2 = np.vstack([verts, verts + [3.0, 0.0, 0.0]])
    f2 = np.vstack([faces, faces + len(verts)])
    np.testing.assert_array_equal(darap.Darap(v2, f2).pins(), [0, len(verts)])


# ---------------------------------------------------------------------------------------------
# The GIL is released during precompute, forward and backward


def other_thread_runs_during(call) -> int:
    """How many times this (main) thread got to run while `call` ran in another thread. With the
    switch interval raised far above the call's duration, a call that holds the GIL lets the
    main thread run 0 times; one that releases it lets the main thread spin. The main thread
    yields the GIL at every turn, so the worker never waits for it."""
    running = threading.Event()
    done = threading.Event()
    error: list[BaseException] = []

    def worker() -> None:
        try:
            running.set()
            call()
        except BaseException as e:  # noqa: BLE001 - reported below
            error.append(e)
        finally:
            running.clear()
            done.set()

    old = sys.getswitchinterval()
    sys.setswitchinterval(5.0)
    try:
        t = threading.Thread(target=worker)
        t.start()
        spins = 0
        while not done.is_set():
            if running.is_set():
                spins += 1
            time.sleep(0)  # lets the worker take the GIL whenever it asks for it
        t.join()
    finally:
        sys.setswitchinterval(old)
    if error:
        raise error[0]
    return spins


def test_gil_is_released_in_precompute_forward_and_backward(rng: np.random.Generator) -> None:
    verts, faces = darap.icosphere(5)  # 10k vertices: each call takes milliseconds
    layer = darap.Darap(verts, faces)
    x = tilted_targets(layer, rng)
    out = layer.forward(x)
    g = rng.standard_normal(x.shape)
    assert other_thread_runs_during(lambda: [darap.Darap(verts, faces) for _ in range(3)]) > 0
    assert other_thread_runs_during(lambda: [layer.forward(x) for _ in range(5)]) > 0
    assert other_thread_runs_during(lambda: [layer.backward(out, g) for _ in range(5)]) > 0


# ---------------------------------------------------------------------------------------------
# Errors: Python exceptions with the Rust messages, never a crash


def test_bad_vertex_arrays_raise() -> None:
    verts, faces = darap.icosphere(1)
    with pytest.raises(ValueError, match=r"verts must have shape \(V, 3\), got an array of shape \(42, 2\)"):
        darap.Darap(verts[:, :2], faces)
    with pytest.raises(ValueError, match=r"verts must have shape \(V, 3\), got an array of shape \(126,\)"):
        darap.Darap(verts.reshape(-1), faces)
    with pytest.raises(TypeError, match="verts must be a NumPy array of dtype float64 or float32, got dtype int64"):
        darap.Darap(verts.astype(np.int64), faces)
    with pytest.raises(TypeError, match=r"and shape \(V, 3\), got list"):
        darap.Darap(verts.tolist(), faces)
    with pytest.raises(TypeError, match="dtype float64 or float32, got dtype >f8"):
        darap.Darap(verts.astype(">f8"), faces)
    bad = verts.copy()
    bad[7, 1] = np.nan
    with pytest.raises(darap.DarapError, match="non-finite value at vertex 7"):
        darap.Darap(bad, faces)


def test_bad_face_arrays_raise() -> None:
    verts, faces = darap.icosphere(1)
    with pytest.raises(TypeError, match="faces must be a NumPy array of dtype int32, int64, uint32 or uint64, got dtype float64"):
        darap.Darap(verts, faces.astype(np.float64))
    with pytest.raises(ValueError, match=r"faces must have shape \(F, 3\), got an array of shape \(80, 4\)"):
        darap.Darap(verts, np.hstack([faces, faces[:, :1]]))
    out_of_range = faces.copy()
    out_of_range[5, 2] = 42
    with pytest.raises(darap.DarapError, match="face 5 refers to vertex 42, but the mesh has only 42 vertices"):
        darap.Darap(verts, out_of_range)
    negative = faces.copy()
    negative[3, 0] = -1
    with pytest.raises(ValueError, match="face 3 refers to vertex -1, which is not a valid vertex index"):
        darap.Darap(verts, negative)
    with pytest.raises(darap.DarapError, match="the mesh has no faces"):
        darap.Darap(verts, np.zeros((0, 3), dtype=np.int64))


def test_singular_laplacian_raises() -> None:
    # A flat fan of zero-area triangles: every cotangent weight is 0, the pinned Laplacian singular.
    verts = np.zeros((4, 3))
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1]], dtype=np.int64)
    with pytest.raises(darap.DarapError, match="not numerically positive definite|referenced by no face|singular"):
        darap.Darap(verts, faces)


def test_bad_targets_and_gradients_raise(rng: np.random.Generator) -> None:
    layer = sphere_layer(1)
    x = tilted_targets(layer, rng)
    with pytest.raises(ValueError, match=r"x must have shape \(42, 3\), got an array of shape \(41, 3\)"):
        layer.forward(x[:-1])
    bad = x.copy()
    bad[5, 0] = np.inf
    with pytest.raises(darap.DarapError, match="target 5 is not finite"):
        layer.forward(bad)
    out = layer.forward(x)
    with pytest.raises(ValueError, match=r"grad_positions must have shape \(42, 3\)"):
        layer.backward(out, np.ones((42, 2)))
    with pytest.raises(TypeError, match="grad_positions must be a NumPy array"):
        layer.backward(out, np.ones((42, 3), dtype=np.int32))
    with pytest.raises(TypeError):
        layer.backward(x, x)  # not a Deformation
    other = sphere_layer(1)
    with pytest.raises(ValueError, match="computed by another Darap layer"):
        other.backward(out, x)


def test_bad_options_raise() -> None:
    verts, faces = darap.icosphere(1)
    with pytest.raises(ValueError, match='rotation_rule must be "gis" or "procrustes", got "kabsch"'):
        darap.Darap(verts, faces, rotation_rule="kabsch")
    with pytest.raises(ValueError, match="post_process must be"):
        darap.Darap(verts, faces, post_process="rescale")
    with pytest.raises(ValueError, match="lam must be a finite number >= 0, got NaN"):
        darap.Darap(verts, faces, lam=float("nan"))
    with pytest.raises(ValueError, match="lam must be a finite number >= 0, got -1"):
        darap.Darap(verts, faces, lam=-1.0)
    layer = darap.Darap(verts, faces)
    with pytest.raises(ValueError, match="lam must be a finite number >= 0, got inf"):
        layer.set_lambda(float("inf"))
    with pytest.raises(ValueError, match="lam must be a finite number >= 0, got -0.5"):
        layer.set_lambda(-0.5)
    assert layer.lam == 8.0
    with pytest.raises(ValueError, match=r"mask must have shape \(42,\)"):
        darap.Darap(verts, faces, mask=np.ones(41, dtype=bool))
    with pytest.raises(TypeError, match="mask must be a NumPy array of dtype bool"):
        darap.Darap(verts, faces, mask=np.ones(42, dtype=np.int64))
    with pytest.raises(ValueError, match="icosphere level must be at most 7"):
        darap.icosphere(8)


# ---------------------------------------------------------------------------------------------
# Normalization and saved files


def test_normalize_side2_cube() -> None:
    obj_verts, _ = read_obj(GOLDEN / "bunny.obj")
    normalized, centre, scale = darap.normalize_side2_cube(obj_verts)
    lo, hi = normalized.min(axis=0), normalized.max(axis=0)
    assert abs((hi - lo).max() - 2.0) < 1e-12
    np.testing.assert_allclose(lo + hi, 0.0, atol=1e-12)
    np.testing.assert_allclose((obj_verts - centre) * scale, normalized, rtol=0, atol=1e-15)
    # The golden saved file holds the same normalization, rounded to float32.
    saved = darap.load_saved(GOLDEN / "bunny_targets.npz")
    np.testing.assert_allclose(saved.verts, normalized, atol=1e-6)
    flat, centre0, scale0 = darap.normalize_side2_cube(np.ones((3, 3)))
    assert scale0 == 1.0 and not flat.any() and list(centre0) == [1.0, 1.0, 1.0]


def test_load_saved_reads_the_golden_file(golden_npz: Path) -> None:
    saved = darap.load_saved(golden_npz)
    assert saved.verts.shape == (1839, 3) and saved.verts.dtype == np.float32
    assert saved.faces.shape == (3674, 3) and saved.faces.dtype == np.int64
    assert saved.verts_normals.shape == (1839, 3)
    assert saved.lam == 8.0 and saved.rotation_rule == "gis" and saved.normalize_target_normals
    assert saved.csd_cfg()["arap_energy_type"] == "spokes_and_rims_mine"
    assert saved.extra == {}
    assert saved.layer().lam == 8.0


def write_saved(path: Path, **overrides) -> Path:
    with np.load(GOLDEN / "bunny_targets.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays.update(overrides)
    arrays = {k: v for k, v in arrays.items() if v is not None}
    np.savez(path, **arrays)
    return path


def test_load_saved_keeps_extra_keys_and_reads_the_rotation_rule(tmp_path: Path) -> None:
    path = write_saved(tmp_path / "p.npz", rotation_rule=np.array("procrustes"), seed=np.array(7))
    saved = darap.load_saved(path)
    assert saved.rotation_rule == "procrustes" and set(saved.extra) == {"rotation_rule", "seed"}
    assert saved.layer().rotation_rule == "procrustes"


def test_load_saved_errors_name_the_file_and_key(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        darap.load_saved(tmp_path / "missing.npz")
    not_npz = tmp_path / "text.npz"
    not_npz.write_text("hello")
    with pytest.raises(ValueError, match="text.npz"):
        darap.load_saved(not_npz)
    with pytest.raises(ValueError, match=r"missing key\(s\) `faces`"):
        darap.load_saved(write_saved(tmp_path / "a.npz", faces=None))
    with np.load(GOLDEN / "bunny_targets.npz") as z:
        faces = z["faces"].copy()
    faces[10, 1] = 5000
    with pytest.raises(ValueError, match=r"face 10 = \[.*5000.*\] refers to a vertex beyond the 1839"):
        darap.load_saved(write_saved(tmp_path / "b.npz", faces=faces))
    with pytest.raises(ValueError, match="`verts_normals` has 1838 rows but `verts` has 1839"):
        darap.load_saved(write_saved(tmp_path / "c.npz", verts_normals=np.ones((1838, 3), np.float32)))
    with pytest.raises(ValueError, match=r"`verts` must have shape \(N, 3\)"):
        darap.load_saved(write_saved(tmp_path / "d.npz", verts=np.ones((1839, 2), np.float32)))
    cfg = '{"local_step_procrustes": {"lamb": 8.0, "normalize_target_normals": false}}'
    saved = darap.load_saved(write_saved(tmp_path / "e.npz", deform_by_csd_cfg=np.array(cfg)))
    with pytest.raises(ValueError, match="normalize_target_normals` is false"):
        saved.apply()


def test_torch_submodule_is_not_imported_by_darap() -> None:
    code = "import sys, darap; assert 'darap.torch' not in sys.modules; print('ok')"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stderr


def test_darap_torch_without_torch_raises_a_clear_import_error() -> None:
    import importlib.util

    if importlib.util.find_spec("torch") is not None:
        pytest.skip("torch is installed here (tests/test_torch.py covers darap.torch)")
    with pytest.raises(ImportError, match="darap.torch needs PyTorch"):
        import darap.torch  # noqa: F401


def z_up_frame() -> np.ndarray:
    """A ``to_input_frame`` of a z-up input in millimetres with an offset: q ↦ Rᵀ q / s + t."""
    r = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # +z ↦ +y (mesh.up = +z)
    m = np.eye(4)
    m[:3, :3] = r.T * 500.0
    m[:3, 3] = [120.0, -40.0, 2000.0]
    return m


def test_to_input_frame_places_results_as_the_rust_cli_apply(tmp_path: Path) -> None:
    path = write_saved(tmp_path / "framed.npz", to_input_frame=z_up_frame())
    saved = darap.load_saved(path)
    np.testing.assert_array_equal(saved.input_frame, z_up_frame())
    normalized = saved.apply()
    placed = saved.to_input_frame(normalized)
    m = z_up_frame()
    expected = (normalized + saved.rest_positions().mean(axis=0)) @ m[:3, :3].T + m[:3, 3]
    np.testing.assert_allclose(placed, expected, rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match="does not record its input frame"):
        darap.load_saved(GOLDEN / "bunny_targets.npz").to_input_frame(normalized)
    bad = m.copy()
    bad[3, 0] = 1.0
    with pytest.raises(ValueError, match="to_input_frame"):
        darap.load_saved(write_saved(tmp_path / "bad.npz", to_input_frame=bad)).input_frame
    exe = find_stylize()
    if exe is None:
        pytest.skip("no stylize binary in target/ (cargo build --bin stylize) and DARAP_STYLIZE_BIN unset")
    out = tmp_path / "applied.obj"
    subprocess.run([str(exe), "apply", str(path), "-o", str(out)], check=True, capture_output=True, timeout=300)
    cli_positions, _ = read_obj(out)
    err = np.abs(placed - cli_positions).max()
    assert err <= 1e-9 * 2000.0, f"max |Δposition| vs stylize apply = {err:.3e}"

# ---------------------------------------------------------------------------------------------
# Feathered regions: the weights of `stylize run --region-feather` / `stylize apply`


def test_feather_weights_ramp_over_the_rings_inside_the_region() -> None:
    # A strip of triangles 0-1-2-…: vertex k is k hops from vertex 0, the only one outside.
    n = 8
    faces = np.array([[k, k + 1, k + 2] for k in range(n - 2)], dtype=np.int64)
    free = np.ones(n, dtype=bool)
    free[0] = False
    # Hops from vertex 0 in this strip: 1 for vertices 1 and 2, then ⌈k/2⌉.
    hops = np.array([0, 1, 1, 2, 2, 3, 3, 4], dtype=np.float64)
    for rings in (0, 1, 2):
        w = darap.feather_weights(free, faces, rings)
        np.testing.assert_array_equal(w, np.minimum(hops / (rings + 1), 1.0))
    with pytest.raises(darap.DarapError, match="face 0 refers to vertex 2, but the mesh has only 2"):
        darap.feather_weights(np.ones(2, dtype=bool), faces, 1)


def test_region_weights_round_trip_and_feathered_layer_differs_from_the_hard_mask(rng: np.random.Generator) -> None:
    verts, faces = darap.icosphere(2)
    free = verts[:, 0] > -0.2
    w = darap.feather_weights(free, faces, 2)
    assert ((w > 0) & (w < 1)).any()
    layer = darap.Darap(verts, faces)
    assert layer.region_weights() is None
    layer.set_region_weights(w)
    np.testing.assert_array_equal(layer.region_weights(), w)
    x = tilted_targets(layer, rng)
    feathered = layer.forward(x).positions
    layer.set_mask(free)
    hard = layer.forward(x).positions
    assert np.abs(feathered - hard).max() > 1e-6
    layer.set_region_weights(None)
    assert layer.region_weights() is None
    with pytest.raises(darap.DarapError, match=r"region weight \(must lie in \[0, 1\]\)"):
        layer.set_region_weights(np.full(len(verts), 1.5))
    with pytest.raises(ValueError, match=r"region weights must have shape \(162,\)"):
        layer.set_region_weights(np.ones(3))
    with pytest.raises(TypeError, match="region weights must be a NumPy array of dtype float64"):
        layer.set_region_weights(np.ones(len(verts), dtype=np.int64))


def test_feathered_localized_run_reapplies_as_stylize_apply(tmp_path: Path) -> None:
    """A localized, feathered `stylize run` re-applied by `SavedDeformation.apply` (saved region,
    a new region with its own feather, and the whole mesh) equals `stylize apply` at the same λ."""
    exe = find_stylize()
    if exe is None:
        pytest.skip("no stylize binary in target/ (cargo build --bin stylize) and DARAP_STYLIZE_BIN unset")
    verts, faces = darap.icosphere(2)
    mesh = tmp_path / "sphere.obj"
    with mesh.open("w") as f:
        for v in verts:
            f.write("v %.17g %.17g %.17g\n" % tuple(v))
        for t in faces:
            f.write(f"f {t[0] + 1} {t[1] + 1} {t[2] + 1}\n")
    run = tmp_path / "run"
    subprocess.run(
        [str(exe), "run", str(mesh), "--style", "cube", "--out", str(run), "-q",
         "--region", "box:-1,-1,-1,0.2,1,1", "--region-feather", "2",
         "--set", "style.iterations=15", "--set", "run.turntable_gif_frames=0"],
        check=True, capture_output=True, timeout=300,
    )
    saved = darap.load_saved(run / "deformation.npz")
    weights = saved.region_weights()
    assert weights is not None and ((weights > 0) & (weights < 1)).any(), "the run should be feathered"
    assert saved.region_feather == 2
    # The saved weights are the feather of the saved free set (the run's own resolution).
    np.testing.assert_array_equal(darap.feather_weights(weights > 0, saved.faces, 2), weights)
    vfile = tmp_path / "verts.txt"
    chosen = np.flatnonzero(saved.rest_positions()[:, 1] > 0)
    vfile.write_text("\n".join(map(str, chosen)) + "\n")
    chosen_free = np.zeros(len(saved.verts), dtype=bool)
    chosen_free[chosen] = True
    cases = [
        ([], dict()),
        (["--region", f"vertices:{vfile}", "--region-feather", "1"], dict(region=chosen_free, feather=1)),
        (["--region", f"vertices:{vfile}"], dict(region=chosen_free)),  # the saved feather, 2
        (["--no-region"], dict(region="whole")),
    ]
    for k, (args, kwargs) in enumerate(cases):
        out = tmp_path / f"applied{k}.obj"
        subprocess.run([str(exe), "apply", str(run / "deformation.npz"), "-o", str(out), "--lambda", "5", *args],
                       check=True, capture_output=True, timeout=300)
        cli, _ = read_obj(out)
        ours = saved.apply(lam=5.0, **kwargs)
        err = np.abs(ours - cli).max()
        assert err <= 1e-12, f"case {args}: max |Δposition| vs stylize apply = {err:.3e}"
    # The saved region matters: the whole-mesh result differs from the localized one.
    assert np.abs(saved.apply(lam=5.0) - saved.apply(lam=5.0, region="whole")).max() > 1e-4
    with pytest.raises(ValueError, match="selects no vertex"):
        saved.apply(region=np.zeros(len(saved.verts), dtype=bool))


def test_one_layer_is_usable_from_several_threads_at_once(rng: np.random.Generator) -> None:
    """Forward and backward in several threads while another thread changes λ used to raise
    "Already borrowed"; each forward records the λ it ran with, and its result is that λ's."""
    from concurrent.futures import ThreadPoolExecutor

    layer = sphere_layer(2)
    x = tilted_targets(layer, rng)
    g = rng.standard_normal((layer.num_vertices, 3))
    expected = {lam: sphere_layer(2, lam=lam).forward(x).positions for lam in (4.0, 8.0)}

    def work(i: int) -> float:
        if i % 4 == 0:
            layer.set_lambda(4.0 if i % 8 == 0 else 8.0)
            return -1.0
        out = layer.forward(x)
        layer.backward(out, g)
        np.testing.assert_array_equal(out.positions, expected[out.lam])
        return out.lam

    with ThreadPoolExecutor(max_workers=4) as pool:
        lams = list(pool.map(work, range(64)))
    assert {lam for lam in lams if lam >= 0} <= {4.0, 8.0}


# ---------------------------------------------------------------------------------------------
# Self-intersections: the exact check of `stylize mesh check` / `apply`


def test_self_intersections_finds_crossing_faces_and_none_on_a_clean_sphere() -> None:
    # Two triangles that pierce each other (no shared vertex), and a third far away.
    verts = np.array(
        [[0, 0, 0], [2, 0, 0], [0, 2, 0],  # in z = 0
         [0.5, 0.5, -1], [0.5, 0.5, 1], [1.5, 1.5, 1],  # crosses z = 0 inside the first
         [10, 10, 10], [11, 10, 10], [10, 11, 10]],
        dtype=np.float64,
    )
    faces = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8]], dtype=np.int64)
    pairs = darap.self_intersections(verts, faces)
    assert pairs.dtype == np.int64 and pairs.shape == (1, 2)
    np.testing.assert_array_equal(pairs, [[0, 1]])
    # Moved apart: nothing, as an empty (0, 2) array.
    apart = verts.copy()
    apart[3:6, 2] += 5.0
    assert darap.self_intersections(apart, faces).shape == (0, 2)
    # A clean closed mesh has none; pushing one vertex through the far side makes some, each
    # pair once, a < b, sorted.
    sphere, sfaces = darap.icosphere(2)
    assert darap.self_intersections(sphere, sfaces).shape == (0, 2)
    dented = sphere.copy()
    dented[0] = -1.5 * dented[0]
    pairs = darap.self_intersections(dented, sfaces)
    assert len(pairs) > 0
    assert (pairs[:, 0] < pairs[:, 1]).all()
    assert [tuple(p) for p in pairs] == sorted({tuple(p) for p in pairs})


def test_self_intersections_refuses_bad_input() -> None:
    verts, faces = darap.icosphere(1)
    bad = verts.copy()
    bad[3, 1] = np.nan
    with pytest.raises(darap.DarapError, match="self-intersection check"):
        darap.self_intersections(bad, faces)
    with pytest.raises(darap.DarapError, match="self-intersection check"):
        darap.self_intersections(verts, faces[:0])
    with pytest.raises(darap.DarapError):
        darap.self_intersections(verts[:5], faces)


def test_forward_at_strength_one_is_forward_and_only_it_is_differentiable(rng: np.random.Generator) -> None:
    verts, faces = darap.icosphere(2)
    layer = darap.Darap(verts, faces, lam=8.0)
    x = layer.rest_normals() + 0.6 * rng.standard_normal((len(verts), 3))
    plain = layer.forward(x)
    one = layer.forward_at_strength(x, 1.0)
    np.testing.assert_array_equal(plain.positions, one.positions)
    g = rng.standard_normal((len(verts), 3))
    np.testing.assert_array_equal(layer.backward(plain, g), layer.backward(one, g))
    strong = layer.forward_at_strength(x, 2.0)
    assert np.abs(strong.positions - plain.positions).max() > 1e-6
    with pytest.raises(darap.DarapError, match="strength 2"):
        layer.backward(strong, g)
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(darap.DarapError, match="strength"):
            layer.forward_at_strength(x, bad)


def test_forward_at_strength_under_procrustes_is_procrustes_at_the_scaled_lambda(rng: np.random.Generator) -> None:
    verts, faces = darap.icosphere(2)
    layer = darap.Darap(verts, faces, lam=5.0, rotation_rule="procrustes")
    x = layer.rest_normals() + 0.6 * rng.standard_normal((len(verts), 3))
    strong = layer.forward_at_strength(x, 3.0).positions
    layer.set_lambda(15.0)
    np.testing.assert_allclose(strong, layer.forward(x).positions, rtol=0, atol=1e-12)


@pytest.mark.parametrize("strength", [1.0, 2.5])
def test_saved_apply_with_strength_matches_rust_cli_apply(golden_npz: Path, tmp_path: Path, strength: float) -> None:
    exe = find_stylize()
    if exe is None:
        pytest.skip("no stylize binary in target/ (cargo build --bin stylize) and DARAP_STYLIZE_BIN unset")
    out = tmp_path / "strong.obj"
    cmd = [str(exe), "apply", str(golden_npz), "-o", str(out), "--strength", str(strength)]
    subprocess.run(cmd, check=True, capture_output=True, timeout=300)
    cli_positions, _ = read_obj(out)
    positions = darap.load_saved(golden_npz).apply(strength=strength)
    assert np.abs(positions - cli_positions).max() <= 1e-12
    with pytest.raises(ValueError, match="strength"):
        darap.load_saved(golden_npz).apply(strength=0.5)
