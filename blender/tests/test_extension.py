"""The Blender extension, headless: the built zip installed into the PyPI `bpy` module (Blender
4.5 LTS, .venv-blender/ from scripts/setup.sh), driven through its operators and properties against
the debug `stylize` binary of the workspace build.

Run: scripts/build_blender_extension.sh, then
     .venv-blender/bin/python -m pytest blender/tests
Environment: GIS_EXTENSION_ZIP (default target/blender/geometry_in_style-*.zip), GIS_STYLIZE_BIN
(default target/debug/stylize, else target/release/stylize).
"""

from __future__ import annotations

import atexit
import glob
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
# Blender's user folders (extensions, config) in a throw-away place, before bpy is imported (removed
# at exit: each holds the installed extension, about 21 MB).
os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="gis-blender-user-")
atexit.register(shutil.rmtree, os.environ["BLENDER_USER_RESOURCES"], True)

import bpy  # noqa: E402
from mathutils import Matrix  # noqa: E402

MODULE = "bl_ext.user_default.geometry_in_style"


def _zip() -> Path:
    env = os.environ.get("GIS_EXTENSION_ZIP")
    if env:
        return Path(env)
    found = sorted(glob.glob(str(REPO / "target" / "blender" / "geometry_in_style-*.zip")))
    if not found:
        pytest.fail("no built extension: run scripts/build_blender_extension.sh (or set GIS_EXTENSION_ZIP)")
    return Path(found[-1])


def _stylize() -> Path:
    env = os.environ.get("GIS_STYLIZE_BIN")
    if env:
        return Path(env)
    for profile in ("debug", "release"):
        exe = REPO / "target" / profile / "stylize"
        if exe.is_file():
            return exe
    pytest.fail("no stylize binary in target/ (cargo build --bin stylize) and GIS_STYLIZE_BIN unset")


@pytest.fixture(scope="module")
def ext(tmp_path_factory):
    result = bpy.ops.extensions.package_install_files(filepath=str(_zip()), repo="user_default", enable_on_install=True)
    assert result == {"FINISHED"}
    mod = sys.modules[MODULE]
    prefs = bpy.context.preferences.addons[MODULE].preferences
    prefs.stylize_path = str(_stylize())
    prefs.runs_dir = str(tmp_path_factory.mktemp("gis-runs"))  # pytest keeps the last 3
    return mod


def read_obj(path) -> tuple[np.ndarray, np.ndarray]:
    verts, faces = [], []
    for line in Path(path).read_text().splitlines():
        parts = line.split()
        if parts and parts[0] == "v":
            verts.append([float(c) for c in parts[1:4]])
        elif parts and parts[0] == "f":
            faces.append([int(p.split("/")[0]) - 1 for p in parts[1:4]])
    return np.array(verts), np.array(faces, dtype=np.int64)


def quad_sphere(name: str):
    """A UV sphere of quads and triangle fans (n-gons get triangulated on export), moved off the
    origin and scaled unevenly in its *local* coordinates, so the side-2 frame is not the object's."""
    bpy.ops.object.select_all(action="DESELECT") if bpy.context.view_layer.objects.active else None
    mesh = bpy.data.meshes.new(name)
    import bmesh

    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=12, v_segments=8, radius=1.0)
    bm.to_mesh(mesh)
    bm.free()
    mesh.transform(Matrix.Translation((3.0, -1.0, 2.0)) @ Matrix.Diagonal((1.5, 1.0, 0.8, 1.0)))
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    return obj


def rest_verts(obj) -> np.ndarray:
    v = np.empty(len(obj.data.vertices) * 3)
    obj.data.vertices.foreach_get("co", v)
    return v.reshape(-1, 3)


def shape_key(obj, name="Stylized") -> np.ndarray:
    key = obj.data.shape_keys.key_blocks[name]
    v = np.empty(len(key.data) * 3, dtype=np.float32)
    key.data.foreach_get("co", v)
    return v.reshape(-1, 3).astype(np.float64)


def to_object_frame(positions: np.ndarray, run_dir: Path, object_rest: np.ndarray) -> np.ndarray:
    """A CLI output (mesh.obj, stylize apply) in the object's local frame, computed here
    independently of the extension: the run's config says which frame its outputs are in
    (`run.output_frame`, absent before outputs moved to the input's frame); a normalized output is
    the side-2 frame with the rest mesh's vertex centroid at the origin (docs/formats.md)."""
    config = tomllib.loads((run_dir / "config.toml").read_text())
    if config.get("run", {}).get("output_frame", "normalized") == "input":
        return positions
    lo, hi = object_rest.min(axis=0), object_rest.max(axis=0)
    centre, scale = (lo + hi) / 2, 2.0 / (hi - lo).max()
    import darap

    saved = darap.load_saved(run_dir / "deformation.npz")
    return (positions + saved.rest_positions().mean(axis=0)) / scale + centre


def close(a: np.ndarray, b: np.ndarray, obj_rest: np.ndarray) -> float:
    """Largest difference relative to the object's size (shape keys are float32)."""
    diag = np.linalg.norm(obj_rest.max(axis=0) - obj_rest.min(axis=0))
    return float(np.abs(a - b).max() / diag)


def apply_cli(run_dir: Path, out: Path, lam: float) -> tuple[np.ndarray, str]:
    done = subprocess.run(
        [str(_stylize()), "apply", str(run_dir / "deformation.npz"), "-o", str(out), "--lambda", repr(lam)],
        check=True, capture_output=True, text=True, timeout=300,
    )
    return read_obj(out)[0], done.stdout + done.stderr


def test_installs_and_registers(ext) -> None:
    import darap

    assert hasattr(bpy.types.Object, "gis")
    assert hasattr(bpy.types, "GIS_PT_panel")
    assert "extensions" in darap.__file__, f"darap should come from the bundled wheel, got {darap.__file__}"
    assert hasattr(darap, "feather_weights")


def test_stylize_cube_shape_key_equals_cli_mesh_obj_and_slider_equals_apply(ext, tmp_path) -> None:
    obj = quad_sphere("Ball")
    rest = rest_verts(obj)
    assert any(len(p.vertices) == 4 for p in obj.data.polygons), "the test mesh should have quads"
    obj.gis.style = "CUBE"
    obj.gis.iterations = 20
    assert bpy.ops.gis.stylize() == {"FINISHED"}, obj.gis.status
    run_dir = Path(obj[ext.RUN_DIR_KEY])
    assert (run_dir / "run.json").is_file()
    # Connectivity unchanged: the run's faces are the object's triangulation.
    obj.data.calc_loop_triangles()
    tris = np.array([t.vertices[:] for t in obj.data.loop_triangles])
    cli, cli_faces = read_obj(run_dir / "mesh.obj")
    np.testing.assert_array_equal(cli_faces, tris)
    np.testing.assert_array_equal(rest_verts(obj), rest)  # the basis is untouched
    expected = to_object_frame(cli, run_dir, rest)
    got = shape_key(obj)
    assert close(got, expected, rest) < 1e-6
    assert close(got, rest, rest) > 1e-3, "the cube style should move the surface"
    assert obj.gis.strength == pytest.approx(8.0)

    # The slider re-applies in-process: equal to `stylize apply` at that λ, sanity line included.
    obj.gis.strength = 3.0
    cli5, printed = apply_cli(run_dir, tmp_path / "l3.obj", 3.0)
    assert close(shape_key(obj), to_object_frame(cli5, run_dir, rest), rest) < 1e-6
    numbers = obj.gis.sanity.split(":", 1)[1]
    assert numbers in printed, f"panel {obj.gis.sanity!r} vs CLI {printed!r}"
    assert obj.gis.warnings == ""
    # A collapsing λ shows the CLI's warnings in the panel.
    obj.gis.strength = 60.0
    _cli60, printed60 = apply_cli(run_dir, tmp_path / "l60.obj", 60.0)
    assert obj.gis.sanity.split(":", 1)[1] in printed60
    for symptom in ("collapsing", "flipped"):
        assert symptom in printed60 and symptom in obj.gis.warnings, (printed60, obj.gis.warnings)
    # The panel's line counts the result's self-intersections (in-process, darap's exact check)
    # as the CLI does, and warns about new ones exactly when the CLI does.
    assert "self-intersections:" in obj.gis.sanity
    assert ("new self-intersecting" in printed60) == ("new self-intersecting" in obj.gis.warnings)

    # Write λ: `stylize apply` at the slider's λ.
    obj.gis.strength = 3.0
    assert bpy.ops.gis.write_lambda() == {"FINISHED"}
    written, _ = read_obj(obj["stylize_written"])
    np.testing.assert_allclose(written, cli5, atol=1e-12)
    # The panel shows what `stylize apply` printed for it (self-intersections included when the
    # binary reports them).
    cli_line = next(l.strip() for l in printed.splitlines() if ": volume ratio" in l)
    assert obj.gis.written_report.split(" | ")[0] == cli_line
    labels = [r[1] for r in draw_panel(ext, obj) if r[0] == "label"]
    start = next(i for i, t in enumerate(labels) if t.startswith("stylize apply → mesh_lambda3.obj"))
    shown, k = [], start + 1
    while len(" ".join(shown)) < len(cli_line):
        shown.append(labels[k])
        k += 1
    assert " ".join(shown) == cli_line, (shown, cli_line)


def test_feathered_vertex_group_region_reapplies_as_stylize_apply(ext, tmp_path) -> None:
    obj = quad_sphere("Top")
    rest = rest_verts(obj)
    group = obj.vertex_groups.new(name="top")
    top = [i for i, v in enumerate(rest) if v[2] > 2.1]
    group.add(top, 1.0, "REPLACE")
    obj.gis.style = "CUBE"
    obj.gis.iterations = 20
    obj.gis.region = "GROUP"
    obj.gis.vertex_group = "top"
    obj.gis.feather = 2
    assert bpy.ops.gis.stylize() == {"FINISHED"}, obj.gis.status
    run_dir = Path(obj[ext.RUN_DIR_KEY])
    import darap

    saved = darap.load_saved(run_dir / "deformation.npz")
    w = saved.region_weights()
    assert w is not None and ((w > 0) & (w < 1)).any(), "a feathered region"
    np.testing.assert_array_equal(np.flatnonzero(w > 0), top)
    cli, _ = read_obj(run_dir / "mesh.obj")
    assert close(shape_key(obj), to_object_frame(cli, run_dir, rest), rest) < 1e-6
    obj.gis.strength = 11.0
    cli11, _ = apply_cli(run_dir, tmp_path / "l11.obj", 11.0)
    assert close(shape_key(obj), to_object_frame(cli11, run_dir, rest), rest) < 1e-6
    # Without the saved region the result would differ: the slider did use it.
    whole = saved.apply(lam=11.0, region="whole")
    assert np.abs(whole - cli11).max() > 1e-4


def test_cancel_checkpoints_and_stylize_resumes(ext) -> None:
    obj = quad_sphere("Slow")
    obj.gis.style = "OCTAHEDRON"
    obj.gis.iterations = 3000
    job = ext.start_job(bpy.context, obj)
    while job.poll() is None and (job.process.iteration or 0) < 10:
        time.sleep(0.01)
    assert job.poll() is None, "the run ended before it could be cancelled"
    assert bpy.ops.gis.cancel() == {"FINISHED"}
    assert job.wait(300) == 143
    with pytest.raises(ext.core.StylizeError, match="cancelled.*Stylize again resumes"):
        job.finish()
    run_dir = obj[ext.RUN_DIR_KEY]
    assert ext.core.run_state(run_dir) == "interrupted"
    # Stylize again: resumes the same run from its checkpoint.
    assert bpy.ops.gis.stylize() == {"FINISHED"}, obj.gis.status
    assert obj[ext.RUN_DIR_KEY] == run_dir
    assert ext.core.run_state(run_dir) == "complete"
    resumed = ext._jobs.get(obj.name)
    assert resumed is None  # finished jobs are dropped
    metrics = [l for l in Path(run_dir, "metrics.jsonl").read_text().splitlines() if l.strip()]
    iterations = [int(re.search(r'"iteration":(\d+)', l).group(1)) for l in metrics]
    assert iterations == sorted(set(iterations)) and iterations[-1] == 3000
    # The second process started after the checkpoint, not at iteration 0 or 1.
    m = re.fullmatch(r"done \(resumed at iteration (\d+)\)", obj.gis.status)
    assert m and int(m.group(1)) >= 10, obj.gis.status


def test_missing_binary_is_reported(ext, monkeypatch) -> None:
    prefs = bpy.context.preferences.addons[MODULE].preferences
    obj = quad_sphere("NoBinary")
    saved_path = prefs.stylize_path
    try:
        prefs.stylize_path = "/nonexistent/stylize"
        # An ERROR report: bpy raises it as RuntimeError when an operator is called from Python.
        with pytest.raises(RuntimeError, match="does not exist: /nonexistent/stylize"):
            bpy.ops.gis.stylize()
        assert "does not exist: /nonexistent/stylize" in obj.gis.status
        prefs.stylize_path = ""
        monkeypatch.setenv("PATH", "/nonexistent")
        with pytest.raises(RuntimeError, match="was not found.*PATH"):
            bpy.ops.gis.stylize()
        assert "was not found" in obj.gis.status
    finally:
        prefs.stylize_path = saved_path
    assert ext.RUN_DIR_KEY not in obj


class Layout:
    """Records what a panel's draw() puts in its layout (headless Blender has no UI to look at)."""

    def __init__(self, rows=None):
        self.rows = rows if rows is not None else []

    def _child(self, *_a, **_k):
        return Layout(self.rows)

    box = column = row = _child

    def prop(self, data, name, **_k):
        self.rows.append(("prop", name))

    def prop_search(self, data, name, *_a, **_k):
        self.rows.append(("prop", name))

    def label(self, text="", icon="NONE"):
        self.rows.append(("label", text, icon))

    def operator(self, idname, text=None, icon="NONE"):
        self.rows.append(("operator", idname, text))


def draw_panel(ext, obj) -> list:
    bpy.context.view_layer.objects.active = obj

    class Panel:
        layout = Layout()

    ext.GIS_PT_panel.draw(Panel, bpy.context)
    return Panel.layout.rows


def test_panel_rows_follow_the_state(ext, monkeypatch) -> None:
    obj = quad_sphere("PanelBall")
    rows = draw_panel(ext, obj)
    props = [r[1] for r in rows if r[0] == "prop"]
    assert props[:4] == ["style", "iterations", "lam", "region"], props
    assert ("operator", "gis.stylize", "Stylize") in rows
    assert "strength" not in props  # no run yet
    obj.gis.style = "EXEMPLAR"
    obj.gis.region = "GROUP"
    props = [r[1] for r in draw_panel(ext, obj) if r[0] == "prop"]
    assert {"exemplar", "vertex_group", "feather"} <= set(props)
    # After a run: the slider, the sanity line, Write λ.
    obj.gis.style = "CUBE"
    obj.gis.region = "ALL"
    obj.gis.iterations = 5
    assert bpy.ops.gis.stylize() == {"FINISHED"}
    rows = draw_panel(ext, obj)
    assert ("prop", "strength") in rows and ("operator", "gis.write_lambda", None) in rows
    assert any(r[0] == "label" and r[1].startswith("λ = ") for r in rows), rows
    # A missing binary: an error box first, with the message.
    prefs = bpy.context.preferences.addons[MODULE].preferences
    saved_path = prefs.stylize_path
    try:
        prefs.stylize_path = "/nonexistent/stylize"
        rows = draw_panel(ext, obj)
    finally:
        prefs.stylize_path = saved_path
    assert rows[0][0] == "label" and rows[0][2] == "ERROR", rows[:3]
    first_prop = next(i for i, r in enumerate(rows) if r[0] == "prop")
    message = " ".join(r[1] for r in rows[:first_prop])
    assert "does not exist: /nonexistent/stylize" in message, message


def test_region_from_selected_vertices_and_vertex_group(ext) -> None:
    obj = quad_sphere("Regions")
    for v in obj.data.vertices:
        v.select = v.index % 3 == 0
    obj.gis.region = "SELECTED"
    assert ext.region_indices(obj, obj.gis) == [i for i in range(len(obj.data.vertices)) if i % 3 == 0]
    for v in obj.data.vertices:
        v.select = False
    with pytest.raises(ext.core.StylizeError, match="no vertex is selected"):
        ext.region_indices(obj, obj.gis)
    group = obj.vertex_groups.new(name="some")
    group.add([1, 4], 0.5, "REPLACE")
    group.add([5], 0.0, "REPLACE")  # weight 0: not in the region
    obj.gis.region = "GROUP"
    obj.gis.vertex_group = "some"
    assert ext.region_indices(obj, obj.gis) == [1, 4]
    obj.gis.vertex_group = "missing"
    with pytest.raises(ext.core.StylizeError, match="no vertex group 'missing'"):
        ext.region_indices(obj, obj.gis)
    obj.gis.region = "ALL"
    assert ext.region_indices(obj, obj.gis) is None


def test_remeshed_run_comes_back_as_a_new_object(ext) -> None:
    exe = str(_stylize())
    if "--remesh" not in subprocess.run([exe, "run", "--help"], capture_output=True, text=True).stdout:
        pytest.skip("this stylize binary has no --remesh")
    obj = quad_sphere("Remeshed")
    rest = rest_verts(obj)
    obj.gis.iterations = 10
    obj.gis.remesh = "ON"
    assert bpy.ops.gis.stylize() == {"FINISHED"}, obj.gis.status
    new = bpy.data.objects.get("Remeshed_stylized")
    assert new is not None, "a new object for the remeshed result"
    assert obj.data.shape_keys is None, "the original is left alone"
    run_dir = Path(new[ext.RUN_DIR_KEY])
    assert obj[ext.RUN_DIR_KEY] == str(run_dir)
    cli, faces = read_obj(run_dir / "mesh.obj")
    assert len(new.data.vertices) == len(cli) != len(rest)
    got = shape_key(new)
    expected = to_object_frame(cli, run_dir, rest)
    assert close(got, expected, rest) < 1e-6


# ---------------------------------------------------------------------------------------------
# The modal path (invoke → modal): the bpy module runs in background mode with no event loop (it has
# one window, but timers never fire and there is no status bar), so invoke runs to the end in
# execute there (checked below). The test stands in for the event loop: `_modal_possible` says yes,
# and the operator gets what it uses of a window — a window, a window manager (timers, the modal
# handler, the progress cursor) and a workspace (status text) — as recording fakes over the real
# context; the test sends the events itself: TIMER as the 0.2 s timer would, Esc as a key press.
# The operator's own code (invoke, modal, _finish, _cleanup) runs unchanged; Blender's event
# dispatch is what this does not test.


class FakeEvent:
    def __init__(self, type_: str, value: str = "NOTHING"):
        self.type = type_
        self.value = value


class FakeWindowManager:
    def __init__(self):
        self.timers: list = []
        self.handlers: list = []
        self.progress: list = []
        self.progress_open = False

    def event_timer_add(self, step, window=None):
        assert window is not None, "the timer belongs to the window"
        timer = ("timer", step)
        self.timers.append(timer)
        return timer

    def event_timer_remove(self, timer):
        self.timers.remove(timer)

    def modal_handler_add(self, op):
        self.handlers.append(op)
        return True

    def progress_begin(self, lo, hi):
        assert (lo, hi) == (0, 100)
        self.progress_open = True

    def progress_update(self, value):
        assert self.progress_open
        self.progress.append(value)

    def progress_end(self):
        self.progress_open = False


class FakeWorkspace:
    def __init__(self):
        self.status: list = []

    def status_text_set(self, text):
        self.status.append(text)


class WindowContext:
    """``bpy.context`` with a (fake) window, window manager and workspace; everything else real."""

    def __init__(self):
        self.window = object()
        self.window_manager = FakeWindowManager()
        self.workspace = FakeWorkspace()

    def __getattr__(self, name):
        return getattr(bpy.context, name)


def modal_operator(ext):
    """An object running GIS_OT_stylize's own methods (Blender makes operator instances only when
    it runs an operator), recording its reports."""
    cls = ext.GIS_OT_stylize

    class Operator:
        _timer = None
        _job = None
        invoke = cls.invoke
        modal = cls.modal
        execute = cls.execute
        _finish = cls._finish
        _cleanup = cls._cleanup

        def __init__(self):
            self.reports: list = []

        def report(self, kind, message):
            self.reports.append((set(kind), message))

    return Operator()


def drive(op, ctx, until=lambda: False, timeout=300.0):
    """Sends TIMER events every 20 ms until modal() ends the operator (returns its result) or
    ``until()`` holds (returns None)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        result = op.modal(ctx, FakeEvent("TIMER"))
        if result != {"PASS_THROUGH"}:
            return result
        if until():
            return None
        time.sleep(0.02)
    pytest.fail("the modal operator did not end in time")


STATUS = re.compile(r"Stylize (\S+): iteration (\d+)/(\d+) \((\d+)%\) — Esc cancels")


def test_modal_progress_esc_cancels_stylize_again_resumes_and_finishes(ext, monkeypatch) -> None:
    # In the bpy module there is a window but no event loop: not modal.
    assert bpy.app.background and bpy.context.window is not None
    assert not ext._modal_possible(bpy.context)
    monkeypatch.setattr(ext, "_modal_possible", lambda _context: True)
    obj = quad_sphere("Modal")
    rest = rest_verts(obj)
    obj.gis.style = "OCTAHEDRON"
    obj.gis.iterations = 1500
    ctx, op = WindowContext(), modal_operator(ext)
    wm, ws = ctx.window_manager, ctx.workspace
    assert op.invoke(ctx, FakeEvent("LEFTMOUSE", "PRESS")) == {"RUNNING_MODAL"}
    assert wm.handlers == [op] and len(wm.timers) == 1 and wm.progress_open
    # Other events pass through and change nothing.
    assert op.modal(ctx, FakeEvent("MOUSEMOVE")) == {"PASS_THROUGH"} and ws.status == []

    # Progress: the status text and the progress cursor follow the CLI's jsonl iterations.
    def seen():
        return sorted({int(m.group(2)) for t in ws.status if t and (m := STATUS.fullmatch(t))})

    assert drive(op, ctx, until=lambda: len(seen()) >= 3 and seen()[-1] >= 20) is None
    for text in ws.status:
        m = STATUS.fullmatch(text)
        assert m, text
        assert m.group(1) == "Modal" and m.group(3) == "1500"
        assert int(m.group(4)) == round(100 * int(m.group(2)) / 1500)
    assert wm.progress == sorted(wm.progress) and wm.progress[-1] == int(100 * seen()[-1] / 1500)
    assert seen()[-1] < 1500, "the run ended before Esc"

    # Esc: SIGTERM, the CLI checkpoints; the operator ends CANCELLED with a warning, cleaned up.
    assert op.modal(ctx, FakeEvent("ESC", "PRESS")) == {"PASS_THROUGH"}
    assert drive(op, ctx) == {"CANCELLED"}
    assert op.reports == [({"WARNING"}, "Stylize cancelled (checkpoint written: Stylize again resumes)")]
    assert wm.timers == [] and not wm.progress_open and ws.status[-1] is None
    run_dir = obj[ext.RUN_DIR_KEY]
    assert ext.core.run_state(run_dir) == "interrupted"
    assert obj.data.shape_keys is None, "no result from a cancelled run"
    assert "cancelled" in obj.gis.status

    # Stylize again, modal: resumes the same run and finishes with the shape key.
    ctx2, op2 = WindowContext(), modal_operator(ext)
    assert op2.invoke(ctx2, FakeEvent("LEFTMOUSE", "PRESS")) == {"RUNNING_MODAL"}
    assert drive(op2, ctx2) == {"FINISHED"}
    assert ctx2.window_manager.timers == [] and not ctx2.window_manager.progress_open
    assert ctx2.workspace.status[-1] is None
    assert obj[ext.RUN_DIR_KEY] == run_dir and ext.core.run_state(run_dir) == "complete"
    m = re.fullmatch(r"done \(resumed at iteration (\d+)\)", obj.gis.status)
    assert m and int(m.group(1)) >= 20, obj.gis.status
    (kind, message), = op2.reports
    assert kind == {"INFO"} and message.startswith("Stylized Modal: shape key 'Stylized'"), message
    cli, _ = read_obj(Path(run_dir) / "mesh.obj")
    assert close(shape_key(obj), to_object_frame(cli, Path(run_dir), rest), rest) < 1e-6


def test_modal_errors_become_reports(ext, monkeypatch) -> None:
    monkeypatch.setattr(ext, "_modal_possible", lambda _context: True)
    # A CLI that fails after starting: a vertex at NaN (Blender keeps it; the CLI refuses the mesh).
    obj = quad_sphere("ModalBad")
    obj.data.vertices[0].co = (float("nan"), 0.0, 0.0)
    obj.gis.style = "CUBE"
    obj.gis.iterations = 5
    ctx, op = WindowContext(), modal_operator(ext)
    assert op.invoke(ctx, FakeEvent("LEFTMOUSE", "PRESS")) == {"RUNNING_MODAL"}
    assert drive(op, ctx) == {"CANCELLED"}
    (kind, message), = op.reports
    assert kind == {"ERROR"} and message.startswith("stylize run failed (exit 1): error"), message
    assert obj.gis.status == message
    assert ctx.window_manager.timers == [] and not ctx.window_manager.progress_open
    assert obj.data.shape_keys is None
    # A failure to start (no binary): an error report from invoke, no modal handler, no timer.
    prefs = bpy.context.preferences.addons[MODULE].preferences
    saved_path = prefs.stylize_path
    try:
        prefs.stylize_path = "/nonexistent/stylize"
        ctx, op = WindowContext(), modal_operator(ext)
        assert op.invoke(ctx, FakeEvent("LEFTMOUSE", "PRESS")) == {"CANCELLED"}
        (kind, message), = op.reports
        assert kind == {"ERROR"} and "does not exist: /nonexistent/stylize" in message
        assert ctx.window_manager.handlers == [] and ctx.window_manager.timers == []
    finally:
        prefs.stylize_path = saved_path
