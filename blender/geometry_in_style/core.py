"""Everything of the extension that does not need Blender: finding the ``stylize`` binary, the
command line of a run, the OBJ the run reads, the run subprocess and its progress, the frame map
between a run's saved deformation and the object, and the λ sanity numbers.

Kept free of ``bpy`` so that it reads (and could be tested) as plain Python; ``numpy`` and the
bundled ``darap`` wheel are imported where they are needed.

Conventions:

- **Vertex order.** The OBJ written for a run lists ``mesh.vertices`` in Blender's order and the
  triangles of ``mesh.loop_triangles`` (triangulation adds no vertex), so vertex ``i`` of the run
  (``deformation.npz`` ``verts``) is vertex ``i`` of the object, n-gons included. The CLI's repair
  may weld or drop vertices of an unclean mesh; then the counts differ and the result comes back as
  a new object instead of a shape key.
- **Frames.** ``deformation.npz`` and every ``darap`` result live in the normalized side-2 frame
  (docs/formats.md): ``q = (p − c)·s`` with ``c`` the bounding-box centre and ``s = 2 / longest
  side`` of the input, and a ``recenter_rescale`` result has its vertex centroid at the origin. A
  result goes back to the object's local coordinates as ``p = M·(q + q̄_rest)``, ``q̄_rest`` the
  saved rest mesh's vertex centroid, ``M`` the file's ``to_input_frame`` matrix when it records
  one, else the inverse of the side-2 normalization of the object's own rest vertices
  (``p = q/s + c``; uniform scale and translation). Either way the map is checked: ``M`` applied to
  the saved rest mesh must give the object's rest vertices (a mesh edited or reordered since the
  run is refused with a message).
"""

from __future__ import annotations

import json
import os
import queue
import shutil
import signal
import subprocess
import threading
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence

#: Sanity thresholds, as ``stylize apply`` (crates/stylize-cli/src/sanity.rs).
COLLAPSE_VOLUME_RATIO = 0.5
COLLAPSE_AREA_RATIO = 0.5
FLIPPED_WARN_FRACTION = 0.01

#: Largest distance (object units, relative to the rest mesh's bounding-box diagonal) between the
#: object's rest vertices and the saved rest mesh mapped back: the saved vertices are float32.
REST_MATCH_TOLERANCE = 1e-5


class StylizeError(Exception):
    """A problem to report to the user (the message is meant for them)."""


# ---------------------------------------------------------------------------------------------
# The binary


def find_stylize(preference: str = "") -> str:
    """The ``stylize`` executable: the add-on preference when set (it must exist), else ``PATH``."""
    preference = (preference or "").strip()
    if preference:
        path = os.path.abspath(os.path.expanduser(preference))
        if not os.path.isfile(path):
            raise StylizeError(
                f"The stylize binary set in the add-on preferences does not exist: {path} "
                "(Edit > Preferences > Add-ons > Geometry in Style > Stylize binary)"
            )
        if not os.access(path, os.X_OK):
            raise StylizeError(f"The stylize binary set in the add-on preferences is not executable: {path}")
        return path
    found = shutil.which("stylize")
    if found is None:
        raise StylizeError(
            "The stylize binary was not found: set its path in Edit > Preferences > Add-ons > "
            "Geometry in Style, or put it on PATH (build it with `cargo build --release --bin stylize`)"
        )
    return found


@dataclass
class Capabilities:
    """What one ``stylize`` binary offers (from ``--version`` and ``run --help``)."""

    version: str
    features: List[str]
    remesh: bool

    @property
    def text(self) -> bool:
        return "text" in self.features


_capabilities: Dict[tuple, Capabilities] = {}


def capabilities(exe: str) -> Capabilities:
    """``stylize --version`` (``stylize 0.1.0 (features: text, gpu, view)``) and whether ``stylize
    run --help`` lists ``--remesh``; cached per binary path and modification time."""
    try:
        key = (exe, os.stat(exe).st_mtime_ns)
    except OSError as e:
        raise StylizeError(f"cannot read the stylize binary {exe}: {e}") from e
    if key in _capabilities:
        return _capabilities[key]
    try:
        version = subprocess.run([exe, "--version"], capture_output=True, text=True, timeout=30)
        helptext = subprocess.run([exe, "run", "--help"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired) as e:
        raise StylizeError(f"cannot run {exe}: {e}") from e
    if version.returncode != 0:
        raise StylizeError(f"{exe} --version failed: {version.stderr.strip() or version.stdout.strip()}")
    line = version.stdout.strip()
    features: List[str] = []
    if "(features:" in line:
        inner = line.split("(features:", 1)[1].rsplit(")", 1)[0]
        features = [f.strip() for f in inner.split(",") if f.strip()]
    caps = Capabilities(version=line, features=features, remesh="--remesh" in helptext.stdout)
    _capabilities[key] = caps
    return caps


# ---------------------------------------------------------------------------------------------
# Inputs of a run


def write_obj(path: str, verts, triangles) -> None:
    """A plain OBJ (``v`` then ``f``, 1-based) with the vertices in the given order, coordinates
    written with 17 significant digits (float32 Blender coordinates round-trip exactly)."""
    with open(path, "w", encoding="ascii") as f:
        f.write("# written by the Geometry in Style Blender extension\n")
        for v in verts:
            f.write("v %.17g %.17g %.17g\n" % (float(v[0]), float(v[1]), float(v[2])))
        for t in triangles:
            f.write("f %d %d %d\n" % (int(t[0]) + 1, int(t[1]) + 1, int(t[2]) + 1))


def write_vertex_file(path: str, indices: Sequence[int]) -> None:
    """A ``vertices:FILE`` region file: one 0-based index per line."""
    with open(path, "w", encoding="ascii") as f:
        f.write("# region vertices (0-based, the object's vertex order)\n")
        for i in indices:
            f.write(f"{int(i)}\n")


@dataclass
class RunRequest:
    """What the panel asks for; :meth:`command` turns it into ``stylize run`` arguments."""

    mesh: str
    out: str
    style: str = "cube"  # cube | octahedron | exemplar:PATH | (empty with prompt)
    prompt: str = ""
    model: str = ""
    iterations: int = 200
    lam: float = 8.0
    region_file: str = ""
    region_feather: int = 0
    remesh: str = ""  # "" = the CLI's default; only passed when the binary has --remesh
    seed: int = 0
    resume: bool = False
    extra: List[str] = field(default_factory=list)

    def command(self, exe: str) -> List[str]:
        cmd = [exe, "run", self.mesh, "--out", self.out, "--log-format", "jsonl"]
        if self.prompt:
            if not self.model:
                raise StylizeError("A text prompt needs a model directory (see docs/models.md)")
            cmd += ["--prompt", self.prompt, "--model", self.model]
            iterations = f"optim.iterations={int(self.iterations)}"
        else:
            cmd += ["--style", self.style]
            iterations = f"style.iterations={int(self.iterations)}"
        if self.resume:
            # The same mesh, --out and objective; without --set/--seed the run's own config.toml
            # is used (docs/cli.md, --resume), so the settings are the interrupted run's.
            return cmd + ["--resume"]
        cmd += ["--set", iterations]
        cmd += ["--set", f"darap.lambda={float(self.lam)!r}", "--seed", str(int(self.seed))]
        if self.region_file:
            cmd += ["--region", f"vertices:{self.region_file}", "--region-feather", str(int(self.region_feather))]
        if self.remesh:
            cmd += ["--remesh", self.remesh]
        return cmd + list(self.extra)


def run_state(run_dir: str) -> str:
    """``complete`` (``run.json``), ``interrupted`` (``checkpoint.json`` without ``run.json``: a
    Stylize resumes it) or ``none``."""
    if os.path.isfile(os.path.join(run_dir, "run.json")):
        return "complete"
    if os.path.isfile(os.path.join(run_dir, "checkpoint.json")):
        return "interrupted"
    return "none"


# ---------------------------------------------------------------------------------------------
# The run subprocess


class RunProcess:
    """``stylize run`` as a child process: stdout (``--log-format jsonl``, one JSON object per
    iteration) is read by a thread into a queue so the UI never blocks; stderr goes to
    ``stderr.txt`` beside the run (its last lines make the error message)."""

    def __init__(self, cmd: List[str], log_path: str, total: int):
        self.cmd = cmd
        self.total = max(int(total), 1)
        self.iteration: Optional[int] = None
        self.first_iteration: Optional[int] = None  # > 0 when the run resumed from a checkpoint
        self.log_path = log_path
        self._lines: "queue.Queue[str]" = queue.Queue()
        self._log = open(log_path, "w", encoding="utf-8")
        try:
            self.proc = subprocess.Popen(
                cmd, stdout=subprocess.PIPE, stderr=self._log, stdin=subprocess.DEVNULL, text=True, bufsize=1
            )
        except OSError as e:
            self._log.close()
            raise StylizeError(f"cannot start {cmd[0]}: {e}") from e
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.cancelled = False

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:  # read to the end: the CLI never sees a closed pipe
            self._lines.put(line)

    def poll(self) -> Optional[int]:
        """Consumes the progress lines so far; returns the exit status once the process ended
        (and its output was read), else None."""
        while True:
            try:
                line = self._lines.get_nowait()
            except queue.Empty:
                break
            self._progress(line)
        code = self.proc.poll()
        if code is None:
            return None
        self._reader.join(timeout=5)
        if self._reader.is_alive():
            return None
        while not self._lines.empty():
            self._progress(self._lines.get_nowait())
        self._log.close()
        return code

    def _progress(self, line: str) -> None:
        it = parse_progress(line)
        if it is not None:
            self.iteration = it
            if self.first_iteration is None:
                self.first_iteration = it

    @property
    def fraction(self) -> float:
        return 0.0 if self.iteration is None else min(max(self.iteration / self.total, 0.0), 1.0)

    def cancel(self) -> None:
        """SIGTERM: the CLI writes a checkpoint and exits with 143; Stylize again resumes."""
        if self.proc.poll() is None:
            self.cancelled = True
            self.proc.send_signal(signal.SIGTERM)

    def error_text(self, code: int) -> str:
        try:
            with open(self.log_path, encoding="utf-8", errors="replace") as f:
                lines = [l.rstrip() for l in f if l.strip()]
        except OSError:
            lines = []
        errors = [l for l in lines if l.startswith("error")]
        tail = errors[-1:] + lines[-3:] if errors else lines[-4:]
        seen, text = set(), []
        for l in tail:
            if l not in seen:
                seen.add(l)
                text.append(l)
        return f"stylize run failed (exit {code}): " + (" | ".join(text) or "no message")


def parse_progress(line: str) -> Optional[int]:
    """The ``iteration`` of a ``--log-format jsonl`` line (None for anything else)."""
    line = line.strip()
    if not line.startswith("{"):
        return None
    try:
        obj = json.loads(line)
    except ValueError:
        return None
    it = obj.get("iteration") if isinstance(obj, dict) else None
    return it if isinstance(it, int) and not isinstance(it, bool) else None


def apply_report(output: str) -> List[str]:
    """The sanity lines (``λ = …: volume ratio …``, with self-intersection counts where the binary
    reports them) and ``warning:`` lines of ``stylize apply``'s output."""
    lines = [l.strip() for l in output.splitlines()]
    return [l for l in lines if (l.startswith("λ = ") and ": volume ratio" in l) or l.startswith("warning:")]


# ---------------------------------------------------------------------------------------------
# Frames


@dataclass
class FrameMap:
    """``p_object = M[:3, :3] @ (q + rest_centroid) + M[:3, 3]`` for a ``darap`` result ``q``
    (side-2 frame, vertex centroid at the origin); see the module docs."""

    matrix: "object"  # (4, 4) float64
    rest_centroid: "object"  # (3,) float64
    recorded: bool  # True: the file's to_input_frame; False: fitted from the object's rest mesh

    def result_to_object(self, q):
        import numpy as np

        q = np.asarray(q, dtype=np.float64) + self.rest_centroid
        return q @ self.matrix[:3, :3].T + self.matrix[:3, 3]

    def rest_to_object(self, rest):
        import numpy as np

        rest = np.asarray(rest, dtype=np.float64)
        return rest @ self.matrix[:3, :3].T + self.matrix[:3, 3]


def recorded_frame(saved):
    """The saved file's ``to_input_frame`` (4, 4) when it records one (a run made after outputs
    moved to the input's frame), else None."""
    import numpy as np

    m = saved.extra.get("to_input_frame")
    if m is None:
        return None
    m = np.asarray(m, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)) or abs(np.linalg.det(m[:3, :3])) == 0.0:
        raise StylizeError(f"{saved.path}: key `to_input_frame` is not an invertible (4, 4) affine matrix")
    return m


def side2_inverse(object_rest):
    """The inverse of the CLI's side-2 normalization of ``object_rest`` as a (4, 4) matrix."""
    import darap
    import numpy as np

    _normalized, centre, scale = darap.normalize_side2_cube(np.asarray(object_rest, dtype=np.float64))
    m = np.eye(4)
    m[:3, :3] *= 1.0 / scale
    m[:3, 3] = centre
    return m


def frame_map(saved, object_rest=None) -> FrameMap:
    """The map of a saved deformation's results to the object's frame. ``object_rest`` (V, 3): the
    object's rest vertices (None for a new object built from the saved rest mesh: then the file's
    matrix, or the identity scale of the side-2 frame). Raises :class:`StylizeError` when the
    object's rest vertices do not match the saved rest mesh under the map."""
    import numpy as np

    rest = saved.rest_positions()
    m = recorded_frame(saved)
    recorded = m is not None
    if m is None:
        if object_rest is None:
            m = np.eye(4)
        else:
            m = side2_inverse(object_rest)
    fm = FrameMap(matrix=m, rest_centroid=rest.mean(axis=0), recorded=recorded)
    if object_rest is not None:
        object_rest = np.asarray(object_rest, dtype=np.float64)
        if object_rest.shape != rest.shape:
            raise StylizeError(
                f"the object has {len(object_rest)} vertices but the run's mesh has {len(rest)}"
            )
        mapped = fm.rest_to_object(rest)
        diag = float(np.linalg.norm(object_rest.max(axis=0) - object_rest.min(axis=0))) or 1.0
        err = float(np.abs(mapped - object_rest).max()) / diag
        if err > REST_MATCH_TOLERANCE:
            raise StylizeError(
                "the object's mesh no longer matches the run (its vertices moved or were reordered "
                f"since; relative deviation {err:.2e}): Stylize again"
            )
    return fm


# ---------------------------------------------------------------------------------------------
# λ sanity (crates/stylize-cli/src/sanity.rs and stylize::eval::pair_ratios, in NumPy)


def _face_areas(p, f):
    import numpy as np

    return 0.5 * np.linalg.norm(np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]), axis=1)


def _signed_volume(p, f):
    import numpy as np

    return float(np.einsum("ij,ij->i", p[f[:, 0]], np.cross(p[f[:, 1]], p[f[:, 2]])).sum() / 6.0)


def _plural(n: int) -> str:
    return "" if n == 1 else "s"


@dataclass
class Intersections:
    """Self-intersection figures of a result against its source (``stylize::intersections``'
    ``IntersectionFigures``, as ``stylize apply`` prints them)."""

    pairs: int
    faces: int
    new_pairs: int
    new_faces: int
    source_pairs: int

    def summary(self) -> str:
        return (
            f"self-intersections: {self.pairs} pair{_plural(self.pairs)} ({self.faces} "
            f"face{_plural(self.faces)}), {self.new_pairs} new"
        )

    def warning(self) -> Optional[str]:
        if self.new_pairs == 0:
            return None
        return (
            f"{self.new_pairs} new self-intersecting face pair{_plural(self.new_pairs)} "
            f"({self.new_faces} face{_plural(self.new_faces)}) that the source does not have "
            f"(the source has {self.source_pairs} pair{_plural(self.source_pairs)})"
        )


def pair_set(pairs) -> frozenset:
    """``darap.self_intersections``' (K, 2) pairs as a set of ``(a, b)`` tuples."""
    return frozenset(map(tuple, pairs.tolist()))


def intersections(source_pairs: frozenset, positions, faces) -> Intersections:
    """The result's exact self-intersections (``darap.self_intersections``, the check of
    ``stylize apply``) and those of its pairs the source (``source_pairs``, a :func:`pair_set`)
    does not have."""
    import darap
    import numpy as np

    pairs = darap.self_intersections(np.asarray(positions, dtype=np.float64), faces)
    new = pair_set(pairs) - source_pairs
    return Intersections(
        pairs=len(pairs),
        faces=len(np.unique(pairs)),
        new_pairs=len(new),
        new_faces=len({f for p in new for f in p}),
        source_pairs=len(source_pairs),
    )


@dataclass
class Sanity:
    lam: float
    flipped_fraction: float
    volume_ratio: float
    area_ratio_mean: float
    area_ratio_std: float
    intersections: Optional[Intersections] = None

    def summary(self) -> str:
        line = (
            f"λ = {self.lam:g}: volume ratio {self.volume_ratio:.3f}, face-area ratio "
            f"{self.area_ratio_mean:.3f} ± {self.area_ratio_std:.3f}, "
            f"{100.0 * self.flipped_fraction:.1f}% of vertices flipped (rotation > 90°)"
        )
        if self.intersections is not None:
            line += ", " + self.intersections.summary()
        return line

    def warnings(self) -> List[str]:
        import math

        out = []
        v = self.volume_ratio
        if math.isfinite(v) and v < COLLAPSE_VOLUME_RATIO:
            out.append(f"collapsing: volume ratio {v:.3f} (below {COLLAPSE_VOLUME_RATIO}); try a smaller λ")
        elif math.isfinite(v) and v > 1.0 / COLLAPSE_VOLUME_RATIO:
            out.append(f"inflating: volume ratio {v:.3f} (above {1.0 / COLLAPSE_VOLUME_RATIO:g}); try a smaller λ")
        if self.area_ratio_mean < COLLAPSE_AREA_RATIO:
            out.append(f"faces shrinking: mean face-area ratio {self.area_ratio_mean:.3f}; try a smaller λ")
        if self.flipped_fraction > FLIPPED_WARN_FRACTION:
            out.append(f"{100.0 * self.flipped_fraction:.1f}% of the rotations flipped (> 90°); try a smaller λ")
        w = self.intersections.warning() if self.intersections is not None else None
        if w is not None:
            out.append(f"{w}; try a smaller λ")
        return out


def sanity(rest, faces, deformation, lam: float, source_pairs=None) -> Sanity:
    """The numbers ``stylize apply`` prints after each output, for a ``darap.Deformation`` of the
    saved rest mesh ``rest`` (side-2 frame); with ``source_pairs`` (the rest mesh's
    ``darap.self_intersections`` as a :func:`pair_set`) also the result's self-intersections, new ones counted against
    those."""
    import darap
    import numpy as np

    faces = np.asarray(faces, dtype=np.int64)
    src, _c, _s = darap.normalize_side2_cube(np.asarray(rest, dtype=np.float64))
    res = deformation.positions - deformation.positions.mean(axis=0)
    d_src = np.linalg.norm(src.max(axis=0) - src.min(axis=0))
    d_res = np.linalg.norm(res.max(axis=0) - res.min(axis=0))
    res = res * (d_src / d_res) if d_res > 0 else res
    a_src, a_res = _face_areas(src, faces), _face_areas(res, faces)
    keep = a_src > 0
    ratios = a_res[keep] / a_src[keep]
    v_src = _signed_volume(src, faces)
    volume = _signed_volume(res, faces) / v_src if v_src != 0 else float("nan")
    rot = deformation.rotations
    flipped = np.trace(rot, axis1=1, axis2=2) < 1.0
    return Sanity(
        lam=float(lam),
        flipped_fraction=float(flipped.mean()) if len(flipped) else 0.0,
        volume_ratio=volume,
        area_ratio_mean=float(ratios.mean()) if ratios.size else float("nan"),
        area_ratio_std=float(ratios.std()) if ratios.size else float("nan"),
        intersections=(
            intersections(source_pairs, deformation.positions, faces) if source_pairs is not None else None
        ),
    )
