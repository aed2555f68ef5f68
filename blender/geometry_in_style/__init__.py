"""Geometry in Style for Blender: stylize a mesh object with the ``stylize`` CLI and re-apply the
result at any strength λ in-process with the bundled ``darap`` module (docs/blender.md).

The panel lives in the 3D viewport's N-sidebar, tab "Stylize". **Stylize** writes the object's
mesh (local coordinates, Blender's vertex order, ``loop_triangles``) to an OBJ, runs ``stylize run
--log-format jsonl`` as a child process polled by a modal timer (progress in the status bar, Esc or
Cancel sends SIGTERM: the CLI checkpoints, and Stylize again resumes), and brings the result back as
the shape key "Stylized" (or, when the CLI changed the vertex count, on a new object). The
strength slider re-applies ``deformation.npz`` through ``darap`` and rewrites the shape key live;
"Write λ" runs ``stylize apply`` at the chosen λ. In background mode (``blender -b``, the ``bpy``
module) Stylize runs to the end before returning, so scripts and tests can drive it.
"""

from __future__ import annotations

import os
import re
import subprocess
import tempfile
import time
from typing import Dict, Optional

import bpy
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

from . import core

#: The custom property that records an object's run directory.
RUN_DIR_KEY = "stylize_run_dir"
SHAPE_KEY = "Stylized"
POLL_SECONDS = 0.2

# Jobs by object name, and re-application layers by (run dir, file mtime).
_jobs: Dict[str, "Job"] = {}
_layers: Dict[str, tuple] = {}
# run directory -> (the SavedDeformation it was computed for, its rest mesh's intersecting pairs)
_source_pairs: Dict[str, tuple] = {}


def _prefs(context) -> "GIS_Preferences":
    return context.preferences.addons[__package__].preferences


# ---------------------------------------------------------------------------------------------
# Properties


def _mesh_poll(_self, obj) -> bool:
    return obj.type == "MESH"


def _strength_changed(self, context) -> None:
    obj = self.id_data
    if self.suspend_update or RUN_DIR_KEY not in obj:
        return
    try:
        apply_strength(obj, self.strength)
    except (core.StylizeError, ValueError, OSError) as e:
        self.sanity = ""
        self.warnings = f"cannot re-apply: {e}"


class GIS_ObjectSettings(bpy.types.PropertyGroup):
    style: EnumProperty(
        name="Style",
        items=[
            ("CUBE", "Cube", "Model-free style: faces turn toward the axes"),
            ("OCTAHEDRON", "Octahedron", "Model-free style: faces turn toward the octahedron's normals"),
            ("EXEMPLAR", "Exemplar", "Model-free style: the normals of an exemplar mesh object"),
            ("PROMPT", "Text prompt", "Text-guided (needs a stylize binary with the `text` feature and a model directory)"),
        ],
        default="CUBE",
    )
    exemplar: PointerProperty(name="Exemplar", type=bpy.types.Object, poll=_mesh_poll)
    prompt: StringProperty(name="Prompt", default="")
    model_dir: StringProperty(name="Model", subtype="DIR_PATH", default="")
    iterations: IntProperty(name="Iterations", default=200, min=1, soft_max=5000)
    lam: FloatProperty(name="λ", description="Strength λ of the run (darap.lambda)", default=8.0, min=0.0, soft_max=40.0)
    region: EnumProperty(
        name="Region",
        items=[
            ("ALL", "Whole mesh", "Every vertex may rotate"),
            ("SELECTED", "Selected vertices", "The selected vertices (vertices:FILE)"),
            ("GROUP", "Vertex group", "The vertices of a vertex group with weight > 0 (vertices:FILE)"),
        ],
        default="ALL",
    )
    vertex_group: StringProperty(name="Group", default="")
    feather: IntProperty(name="Feather", description="Rings over which λ fades at the region's boundary (--region-feather)", default=0, min=0, soft_max=10)
    remesh: EnumProperty(
        name="Remesh",
        items=[
            ("OFF", "Off", "Keep the connectivity (the result is a shape key)"),
            ("AUTO", "Auto", "The CLI remeshes when it advises it (the result may be a new object)"),
            ("ON", "On", "Always remesh (the result is a new object)"),
        ],
        default="OFF",
    )
    strength: FloatProperty(
        name="Strength λ",
        description="Re-applies the saved deformation at this λ (live, in-process)",
        default=8.0,
        min=0.0,
        soft_max=30.0,
        update=_strength_changed,
    )
    suspend_update: BoolProperty(default=False, options={"HIDDEN", "SKIP_SAVE"})
    sanity: StringProperty(default="")
    warnings: StringProperty(default="")
    # What `stylize apply` printed for the last Write λ: its sanity line (with the
    # self-intersection counts where the binary reports them) and warnings, " | "-separated.
    written_report: StringProperty(default="")
    status: StringProperty(default="")


class GIS_Preferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    stylize_path: StringProperty(
        name="Stylize binary",
        subtype="FILE_PATH",
        description="Path of the `stylize` executable (empty: found on PATH)",
        default="",
    )
    runs_dir: StringProperty(
        name="Runs folder",
        subtype="DIR_PATH",
        description="Where run directories are created (empty: `stylize_runs` beside the .blend file, else the temporary folder)",
        default="",
    )

    def draw(self, _context):
        self.layout.prop(self, "stylize_path")
        self.layout.prop(self, "runs_dir")


# ---------------------------------------------------------------------------------------------
# Mesh in, result out


def mesh_arrays(obj):
    """(verts (V, 3) float64 local coordinates, triangles (T, 3) int64) in Blender's order."""
    import numpy as np

    if obj.mode == "EDIT":
        obj.update_from_editmode()
    mesh = obj.data
    verts = np.empty(len(mesh.vertices) * 3, dtype=np.float64)
    mesh.vertices.foreach_get("co", verts)
    mesh.calc_loop_triangles()
    tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int64)
    mesh.loop_triangles.foreach_get("vertices", tris)
    return verts.reshape(-1, 3), tris.reshape(-1, 3)


def region_indices(obj, settings):
    """The region's vertex indices, or None for the whole mesh."""
    if settings.region == "ALL":
        return None
    mesh = obj.data
    if settings.region == "SELECTED":
        idx = [v.index for v in mesh.vertices if v.select]
        if not idx:
            raise core.StylizeError("Region: no vertex is selected")
        return idx
    group = obj.vertex_groups.get(settings.vertex_group)
    if group is None:
        raise core.StylizeError(f"Region: the object has no vertex group {settings.vertex_group!r}")
    gi = group.index
    idx = [v.index for v in mesh.vertices if any(g.group == gi and g.weight > 0.0 for g in v.groups)]
    if not idx:
        raise core.StylizeError(f"Region: the vertex group {group.name!r} holds no vertex")
    return idx


def runs_base(context) -> str:
    base = bpy.path.abspath(_prefs(context).runs_dir) if _prefs(context).runs_dir else ""
    if not base:
        base = os.path.join(os.path.dirname(bpy.data.filepath), "stylize_runs") if bpy.data.filepath else os.path.join(tempfile.gettempdir(), "geometry_in_style")
    return base


def new_job_dir(context, obj) -> str:
    base = runs_base(context)
    os.makedirs(base, exist_ok=True)
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", obj.name) or "object"
    n = 1
    while os.path.exists(os.path.join(base, f"{stem}_{n:03d}")):
        n += 1
    path = os.path.join(base, f"{stem}_{n:03d}")
    os.makedirs(path)
    return path


def shape_key_target(obj, saved):
    """The object the result goes on, and its frame map: ``obj`` itself when the run kept its
    vertices (checked), else a new object built from the run's rest mesh."""
    import numpy as np

    verts, _tris = mesh_arrays(obj)
    if len(verts) == len(saved.verts):
        return obj, core.frame_map(saved, verts)
    # The CLI changed the mesh (repair or remeshing): a new object from the saved rest mesh.
    fm = core.frame_map(saved, None)
    if not fm.recorded:
        fm.matrix = core.side2_inverse(verts)
    rest = fm.rest_to_object(saved.rest_positions())
    mesh = bpy.data.meshes.new(obj.data.name + "_stylized")
    mesh.from_pydata(rest.tolist(), [], np.asarray(saved.faces).tolist())
    mesh.update()
    new = bpy.data.objects.new(obj.name + "_stylized", mesh)
    new.matrix_world = obj.matrix_world.copy()
    for coll in obj.users_collection:
        coll.objects.link(new)
    return new, fm


def write_shape_key(obj, positions) -> None:
    import numpy as np

    if obj.data.shape_keys is None:
        obj.shape_key_add(name="Basis", from_mix=False)
    key = obj.data.shape_keys.key_blocks.get(SHAPE_KEY)
    if key is None:
        key = obj.shape_key_add(name=SHAPE_KEY, from_mix=False)
    key.data.foreach_set("co", np.asarray(positions, dtype=np.float32).ravel())
    key.value = 1.0
    obj.data.update()


def ready(run_dir: str):
    """(saved, layer) for a run directory's deformation.npz, cached until the file changes."""
    import darap

    path = os.path.join(run_dir, "deformation.npz")
    try:
        mtime = os.stat(path).st_mtime_ns
    except OSError as e:
        raise core.StylizeError(f"no saved deformation in {run_dir}: {e}") from e
    cached = _layers.get(run_dir)
    if cached is not None and cached[0] == mtime:
        return cached[1], cached[2]
    saved = darap.load_saved(path)
    layer = saved.layer()  # the saved λ, rule and (feathered) region, as `stylize apply`
    _layers[run_dir] = (mtime, saved, layer)
    return saved, layer


def source_pairs(run_dir: str, saved):
    """The saved rest mesh's self-intersecting face pairs as a ``core.pair_set`` (what a result's
    new pairs are counted against), computed once per loaded deformation."""
    import darap

    cached = _source_pairs.get(run_dir)
    if cached is not None and cached[0] is saved:
        return cached[1]
    pairs = core.pair_set(darap.self_intersections(saved.rest_positions(), saved.faces))
    _source_pairs[run_dir] = (saved, pairs)
    return pairs


def apply_strength(obj, lam: float):
    """Re-applies the object's run at ``lam`` and rewrites its shape key; returns the positions
    (object frame) and records the λ sanity line and warnings on the object."""
    run_dir = obj.get(RUN_DIR_KEY)
    if not run_dir:
        raise core.StylizeError(f"{obj.name} has no stylize run")
    saved, layer = ready(run_dir)
    layer.set_lambda(float(lam))
    deformation = layer.forward(saved.targets())
    verts, _ = mesh_arrays(obj)
    fm = core.frame_map(saved, verts)
    positions = fm.result_to_object(deformation.positions)
    write_shape_key(obj, positions)
    s = core.sanity(saved.rest_positions(), saved.faces, deformation, lam, source_pairs(run_dir, saved))
    obj.gis.sanity = s.summary()
    obj.gis.warnings = " | ".join(s.warnings())
    return positions


def finish_run(obj, run_dir: str):
    """Brings a complete run back: the shape key at the saved λ on ``obj`` (or a new object),
    the run directory recorded. Returns the object that holds the result."""
    _layers.pop(run_dir, None)
    _source_pairs.pop(run_dir, None)
    saved, _layer = ready(run_dir)
    target, _fm = shape_key_target(obj, saved)
    target[RUN_DIR_KEY] = run_dir
    lam = saved.lam if saved.lam is not None else 8.0
    target.gis.suspend_update = True
    target.gis.strength = lam
    target.gis.suspend_update = False
    apply_strength(target, lam)
    if target is not obj:
        obj[RUN_DIR_KEY] = run_dir
    return target


# ---------------------------------------------------------------------------------------------
# Jobs


class Job:
    """One ``stylize run`` of an object (started by :func:`start_job`)."""

    def __init__(self, obj, job_dir: str, run_dir: str, process: core.RunProcess):
        self.object_name = obj.name
        self.job_dir = job_dir
        self.run_dir = run_dir
        self.process = process
        self.code: Optional[int] = None

    def poll(self) -> Optional[int]:
        if self.code is None:
            self.code = self.process.poll()
        return self.code

    def wait(self, timeout: float = 3600.0) -> int:
        deadline = time.monotonic() + timeout
        while self.poll() is None:
            if time.monotonic() > deadline:
                raise core.StylizeError("stylize run did not finish in time")
            time.sleep(0.05)
        return self.code

    def cancel(self) -> None:
        self.process.cancel()

    def status_text(self) -> str:
        it = self.process.iteration
        total = self.process.total
        return f"Stylize {self.object_name}: iteration {0 if it is None else it}/{total} ({100 * self.process.fraction:.0f}%) — Esc cancels"

    def finish(self):
        """After exit: the result object, or raises StylizeError (cancelled or failed)."""
        _jobs.pop(self.object_name, None)
        obj = bpy.data.objects.get(self.object_name)
        code = self.code
        if code in (130, 143) or (self.process.cancelled and code != 0):
            state = core.run_state(self.run_dir)
            raise core.StylizeError(
                "Stylize cancelled"
                + (" (checkpoint written: Stylize again resumes)" if state == "interrupted" else "")
            )
        if code != 0:
            raise core.StylizeError(self.process.error_text(code))
        if obj is None:
            raise core.StylizeError(f"the object {self.object_name} was deleted during the run")
        return finish_run(obj, self.run_dir)


def start_job(context, obj) -> Job:
    """Writes the inputs and starts ``stylize run`` for ``obj`` (resuming its interrupted run)."""
    if obj is None or obj.type != "MESH":
        raise core.StylizeError("Select a mesh object")
    if obj.name in _jobs and _jobs[obj.name].poll() is None:
        raise core.StylizeError(f"{obj.name} is already being stylized")
    settings = obj.gis
    exe = core.find_stylize(_prefs(context).stylize_path)
    caps = core.capabilities(exe)
    verts, tris = mesh_arrays(obj)
    if len(tris) == 0:
        raise core.StylizeError(f"{obj.name} has no faces")
    previous = obj.get(RUN_DIR_KEY)
    resume = bool(previous) and core.run_state(previous) == "interrupted"
    if resume:
        run_dir = previous
        job_dir = os.path.dirname(run_dir)
    else:
        job_dir = new_job_dir(context, obj)
        run_dir = os.path.join(job_dir, "run")
    mesh_path = os.path.join(job_dir, "input.obj")
    core.write_obj(mesh_path, verts, tris)
    req = core.RunRequest(mesh=mesh_path, out=run_dir, iterations=settings.iterations, lam=settings.lam, resume=resume)
    if settings.style == "PROMPT":
        if not caps.text:
            raise core.StylizeError(f"This stylize binary has no `text` feature ({caps.version}): use a model-free style")
        if not settings.prompt.strip():
            raise core.StylizeError("Enter a prompt")
        req.prompt = settings.prompt
        req.model = bpy.path.abspath(settings.model_dir)
    elif settings.style == "EXEMPLAR":
        ex = settings.exemplar
        if ex is None:
            raise core.StylizeError("Pick an exemplar mesh object")
        ev, et = mesh_arrays(ex)
        ex_path = os.path.join(job_dir, "exemplar.obj")
        core.write_obj(ex_path, ev, et)
        req.style = f"exemplar:{ex_path}"
    else:
        req.style = settings.style.lower()
    idx = region_indices(obj, settings)
    if idx is not None:
        req.region_file = os.path.join(job_dir, "region.txt")
        core.write_vertex_file(req.region_file, idx)
        req.region_feather = settings.feather
    if caps.remesh:
        req.remesh = settings.remesh.lower()
    process = core.RunProcess(req.command(exe), os.path.join(job_dir, "stderr.txt"), settings.iterations)
    obj[RUN_DIR_KEY] = run_dir
    job = Job(obj, job_dir, run_dir, process)
    _jobs[obj.name] = job
    settings.status = "resuming" if resume else "running"
    return job


# ---------------------------------------------------------------------------------------------
# Operators


def _modal_possible(context) -> bool:
    """Whether timer events will reach a modal operator: a window and Blender's event loop. In
    background mode there is none (``blender -b`` has no window; the ``bpy`` module has one, but
    neither ``event_timer_add`` timers nor ``bpy.app.timers`` ever fire), so Stylize runs to the end
    in ``execute`` instead."""
    return not bpy.app.background and context.window is not None


class GIS_OT_stylize(bpy.types.Operator):
    """Stylize the active mesh object with the stylize CLI (resumes its interrupted run)"""

    bl_idname = "gis.stylize"
    bl_label = "Stylize"
    bl_options = {"REGISTER"}

    _timer = None
    _job: Optional[Job] = None

    @classmethod
    def poll(cls, context):
        return context.active_object is not None and context.active_object.type == "MESH"

    def _finish(self, context):
        try:
            target = self._job.finish()
        except core.StylizeError as e:
            obj = bpy.data.objects.get(self._job.object_name)
            if obj is not None:
                obj.gis.status = str(e)
            self.report({"WARNING"} if "cancelled" in str(e) else {"ERROR"}, str(e))
            return {"CANCELLED"}
        first = self._job.process.first_iteration
        target.gis.status = "done" + (f" (resumed at iteration {first})" if first and first > 1 else "")
        self.report({"INFO"}, f"Stylized {target.name}: shape key '{SHAPE_KEY}', run {self._job.run_dir}, {target.gis.status}")
        return {"FINISHED"}

    def execute(self, context):
        # Background mode (scripts, tests): run to the end here.
        try:
            self._job = start_job(context, context.active_object)
        except core.StylizeError as e:
            context.active_object.gis.status = str(e)
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        self._job.wait()
        return self._finish(context)

    def invoke(self, context, _event):
        if not _modal_possible(context):
            return self.execute(context)
        try:
            self._job = start_job(context, context.active_object)
        except core.StylizeError as e:
            context.active_object.gis.status = str(e)
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        wm = context.window_manager
        self._timer = wm.event_timer_add(POLL_SECONDS, window=context.window)
        wm.modal_handler_add(self)
        wm.progress_begin(0, 100)
        return {"RUNNING_MODAL"}

    def _cleanup(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        context.workspace.status_text_set(None)

    def modal(self, context, event):
        if event.type == "ESC" and event.value == "PRESS":
            self._job.cancel()
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        code = self._job.poll()
        if code is None:
            context.workspace.status_text_set(self._job.status_text())
            context.window_manager.progress_update(int(100 * self._job.process.fraction))
            return {"PASS_THROUGH"}
        self._cleanup(context)
        return self._finish(context)


class GIS_OT_cancel(bpy.types.Operator):
    """Stop the object's run (SIGTERM: the CLI writes a checkpoint; Stylize again resumes)"""

    bl_idname = "gis.cancel"
    bl_label = "Cancel"

    def execute(self, context):
        obj = context.active_object
        job = _jobs.get(obj.name) if obj else None
        if job is None or job.poll() is not None:
            self.report({"WARNING"}, "No run of this object is going")
            return {"CANCELLED"}
        job.cancel()
        return {"FINISHED"}


class GIS_OT_write_lambda(bpy.types.Operator):
    """Write the result at the chosen λ with `stylize apply` (OBJ beside the run)"""

    bl_idname = "gis.write_lambda"
    bl_label = "Write λ"

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and RUN_DIR_KEY in obj

    def execute(self, context):
        obj = context.active_object
        run_dir = obj[RUN_DIR_KEY]
        lam = obj.gis.strength
        try:
            exe = core.find_stylize(_prefs(context).stylize_path)
        except core.StylizeError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        out = os.path.join(os.path.dirname(run_dir), f"mesh_lambda{lam:g}.obj")
        cmd = [exe, "apply", os.path.join(run_dir, "deformation.npz"), "-o", out, "--lambda", repr(float(lam)), "--force"]
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        if done.returncode != 0:
            self.report({"ERROR"}, f"stylize apply failed: {done.stderr.strip()}")
            return {"CANCELLED"}
        obj["stylize_written"] = out
        obj.gis.written_report = " | ".join(core.apply_report(done.stdout + "\n" + done.stderr))
        self.report({"INFO"}, f"Wrote {out}")
        return {"FINISHED"}


class GIS_OT_forget(bpy.types.Operator):
    """Forget the object's run (the files stay; the next Stylize starts a new run)"""

    bl_idname = "gis.forget"
    bl_label = "Forget run"

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and RUN_DIR_KEY in obj

    def execute(self, context):
        obj = context.active_object
        _layers.pop(obj[RUN_DIR_KEY], None)
        _source_pairs.pop(obj[RUN_DIR_KEY], None)
        del obj[RUN_DIR_KEY]
        obj.gis.sanity = obj.gis.warnings = obj.gis.status = ""
        return {"FINISHED"}


# ---------------------------------------------------------------------------------------------
# Panel


class GIS_PT_panel(bpy.types.Panel):
    bl_label = "Geometry in Style"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Stylize"

    @classmethod
    def poll(cls, context):
        return context.active_object is not None and context.active_object.type == "MESH"

    def draw(self, context):
        layout = self.layout
        obj = context.active_object
        s = obj.gis
        try:
            exe = core.find_stylize(_prefs(context).stylize_path)
            caps = core.capabilities(exe)
        except core.StylizeError as e:
            exe, caps = None, None
            box = layout.box()
            for k, chunk in enumerate(_wrap(str(e))):
                box.label(text=chunk, icon="ERROR" if k == 0 else "NONE")
        col = layout.column()
        col.prop(s, "style")
        if s.style == "EXEMPLAR":
            col.prop(s, "exemplar")
        elif s.style == "PROMPT":
            if caps is not None and not caps.text:
                col.label(text="This stylize binary has no `text` feature", icon="ERROR")
            col.prop(s, "prompt")
            col.prop(s, "model_dir")
        col.prop(s, "iterations")
        col.prop(s, "lam")
        col.prop(s, "region")
        if s.region == "GROUP":
            col.prop_search(s, "vertex_group", obj, "vertex_groups")
        if s.region != "ALL":
            col.prop(s, "feather")
        if caps is not None and caps.remesh:
            col.prop(s, "remesh")
        job = _jobs.get(obj.name)
        row = layout.row()
        if job is not None and job.poll() is None:
            row.label(text=job.status_text())
            row.operator("gis.cancel", icon="CANCEL")
        else:
            state = core.run_state(obj[RUN_DIR_KEY]) if RUN_DIR_KEY in obj else "none"
            row.operator("gis.stylize", text="Resume" if state == "interrupted" else "Stylize", icon="PLAY")
        if s.status:
            layout.label(text=s.status)
        if RUN_DIR_KEY in obj:
            box = layout.box()
            box.label(text=f"Run: {obj[RUN_DIR_KEY]}")
            if core.run_state(obj[RUN_DIR_KEY]) == "complete":
                box.prop(s, "strength", slider=True)
                if s.sanity:
                    for chunk in _wrap(s.sanity):
                        box.label(text=chunk)
                for w in filter(None, s.warnings.split(" | ")):
                    box.label(text=w, icon="ERROR")
                if s.written_report and "stylize_written" in obj:
                    box.label(text=f"stylize apply → {os.path.basename(obj['stylize_written'])}:")
                    for line in s.written_report.split(" | "):
                        for chunk in _wrap(line):
                            box.label(text=chunk, icon="ERROR" if line.startswith("warning") else "NONE")
                row = box.row()
                row.operator("gis.write_lambda")
                row.operator("gis.forget")


def _wrap(text: str, width: int = 60):
    words, lines, line = text.split(), [], ""
    for w in words:
        if line and len(line) + 1 + len(w) > width:
            lines.append(line)
            line = w
        else:
            line = f"{line} {w}" if line else w
    if line:
        lines.append(line)
    return lines or [""]


classes = (
    GIS_ObjectSettings,
    GIS_Preferences,
    GIS_OT_stylize,
    GIS_OT_cancel,
    GIS_OT_write_lambda,
    GIS_OT_forget,
    GIS_PT_panel,
)


def register():
    for c in classes:
        bpy.utils.register_class(c)
    bpy.types.Object.gis = PointerProperty(type=GIS_ObjectSettings)


def unregister():
    for job in list(_jobs.values()):
        job.cancel()
    _jobs.clear()
    _layers.clear()
    _source_pairs.clear()
    del bpy.types.Object.gis
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
