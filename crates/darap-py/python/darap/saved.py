"""The reference's saved-deformation ``.npz`` (spec §8; layout in ``docs/formats.md``), read with NumPy.

| key | dtype, shape | meaning |
|---|---|---|
| ``verts`` | ``<f4`` (V, 3) | rest mesh after side-2 cube normalization |
| ``faces`` | ``<i8`` (F, 3) | CCW triangles, 0-based |
| ``verts_normals`` | ``<f4`` (V, 3) | the raw optimized target normals x (not unit length) |
| ``deform_by_csd_cfg`` | ``<U…`` 0-d | JSON: ``local_step_procrustes.lamb`` (λ), … |
| ``dataset_cfg`` | ``<U…`` 0-d | JSON describing the input |

Any other key (this project writes ``format_version``, ``seed``, ``rotation_rule``,
``to_input_frame``, ``output_frame``, ``up``, …) is kept in :attr:`SavedDeformation.extra`.
``to_input_frame`` (``<f8`` (4, 4)) maps the frame of ``verts`` back to the run's input file's
coordinates: :meth:`SavedDeformation.to_input_frame` places a result there as ``stylize apply``
does by default.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any, Dict, Optional, Union

import numpy as np

from ._darap import Darap, feather_weights, normalize_side2_cube

STANDARD_KEYS = ("verts", "faces", "verts_normals", "deform_by_csd_cfg", "dataset_cfg")

PathLike = Union[str, "os.PathLike[str]"]

#: Which vertices may rotate when re-applying (``stylize::saved::Region``): ``"saved"`` (the run's
#: ``region_weights``, else every vertex: what ``stylize apply`` does by default), ``"whole"``
#: (every vertex, ``--no-region``) or a (V,) bool array of the vertices that may rotate, feathered
#: by ``feather`` rings (default: the run's ``region_feather``, else 0), as ``--mask``/``--region``.
RegionArg = Union[str, np.ndarray]


@dataclass
class SavedDeformation:
    """A saved deformation, arrays as stored (``verts``/``verts_normals`` float32 in the reference).

    ``verts`` were normalized to the side-2 cube in float32 when saved; :meth:`rest_positions`
    renormalizes them in float64, exactly as ``stylize apply`` does, so :meth:`apply` reproduces the
    Rust CLI.
    """

    path: str
    verts: np.ndarray
    faces: np.ndarray
    verts_normals: np.ndarray
    deform_by_csd_cfg: str
    dataset_cfg: str
    extra: Dict[str, np.ndarray] = field(default_factory=dict)

    def csd_cfg(self) -> Dict[str, Any]:
        """The parsed ``deform_by_csd_cfg`` JSON (``{}`` if it is not a JSON object)."""
        try:
            cfg = json.loads(self.deform_by_csd_cfg)
        except ValueError:
            return {}
        return cfg if isinstance(cfg, dict) else {}

    @property
    def lam(self) -> Optional[float]:
        """``local_step_procrustes.lamb``: the λ used in training, if recorded."""
        step = self.csd_cfg().get("local_step_procrustes")
        value = step.get("lamb") if isinstance(step, dict) else None
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        return None

    @property
    def normalize_target_normals(self) -> bool:
        """``local_step_procrustes.normalize_target_normals`` (default True, as the reference)."""
        step = self.csd_cfg().get("local_step_procrustes")
        value = step.get("normalize_target_normals", True) if isinstance(step, dict) else True
        return bool(value)

    @property
    def rotation_rule(self) -> str:
        """The file's ``rotation_rule`` key (written by this project), else ``"gis"``."""
        value = self.extra.get("rotation_rule")
        if value is None:
            return "gis"
        rule = str(value.reshape(-1)[0] if value.size else "").strip().lower()
        if rule not in ("gis", "procrustes"):
            raise ValueError(f"{self.path}: unknown rotation rule {rule!r} in key `rotation_rule`")
        return rule

    def region_weights(self) -> Optional[np.ndarray]:
        """The saved region's per-vertex weights (extra key ``region_weights`` of a localized run,
        feathered as the run was), float64 (V,); ``None`` for a whole-mesh run."""
        value = self.extra.get("region_weights")
        if value is None:
            return None
        if value.dtype.kind != "f" or value.shape != (len(self.verts),):
            raise ValueError(
                f"{self.path}: `region_weights` must hold one f64 per vertex ({len(self.verts)}), "
                f"got dtype {value.dtype} shape {value.shape}"
            )
        return np.asarray(value, dtype=np.float64)

    @property
    def region_feather(self) -> Optional[int]:
        """The saved run's feather rings (extra key ``region_feather``), if recorded."""
        value = self.extra.get("region_feather")
        if value is None or value.size != 1 or value.dtype.kind not in "iu":
            return None
        return int(value.reshape(-1)[0])

    def resolve_region(self, region: RegionArg = "saved", feather: Optional[int] = None) -> Optional[np.ndarray]:
        """The per-vertex weights that ``region`` means (see :data:`RegionArg`), ``None`` for every
        vertex free: exactly the weights ``stylize apply`` gives the layer."""
        if isinstance(region, str):
            if region == "saved":
                return self.region_weights()
            if region == "whole":
                return None
            raise ValueError(f"region must be 'saved', 'whole' or a (V,) bool array, got {region!r}")
        free = np.asarray(region)
        if free.dtype != np.bool_ or free.shape != (len(self.verts),):
            raise ValueError(
                f"region must be a ({len(self.verts)},) bool array (True where a vertex may rotate), "
                f"got dtype {free.dtype} shape {free.shape}"
            )
        if not free.any():
            raise ValueError("the region selects no vertex: a localized apply would change nothing")
        rings = feather if feather is not None else (self.region_feather or 0)
        if rings < 0:
            raise ValueError(f"feather rings must be ≥ 0, got {rings}")
        return feather_weights(free, self.faces, rings)

    def rest_positions(self) -> np.ndarray:
        """``verts`` in float64, normalized to the side-2 cube (longest bbox side [−1, 1], bbox
        centred at the origin), as ``stylize apply`` and the reference do."""
        positions, _centre, _scale = normalize_side2_cube(np.asarray(self.verts, dtype=np.float64))
        return positions

    def targets(self) -> np.ndarray:
        """The raw target normals ``x`` in float64 (only their directions matter)."""
        return np.asarray(self.verts_normals, dtype=np.float64)

    def layer(
        self,
        lam: Optional[float] = None,
        rotation_rule: Optional[str] = None,
        mask: Optional[np.ndarray] = None,
        region: RegionArg = "saved",
        feather: Optional[int] = None,
    ) -> Darap:
        """A :class:`Darap` layer on :meth:`rest_positions` with the saved λ and rotation rule
        unless given (λ 8 when the file records none), and the region of ``region``/``feather``
        (:meth:`resolve_region`; by default the saved one, as ``stylize apply``). A ``mask``
        (hard, unfeathered) replaces the region."""
        if not self.normalize_target_normals:
            raise ValueError(
                f"{self.path}: `normalize_target_normals` is false; only normalized target "
                "normals are supported"
            )
        if lam is None:
            lam = self.lam if self.lam is not None else 8.0
        weights = None if mask is not None else self.resolve_region(region, feather)
        layer = Darap(
            self.rest_positions(),
            self.faces,
            lam=lam,
            rotation_rule=rotation_rule if rotation_rule is not None else self.rotation_rule,
            mask=mask,
        )
        if weights is not None:
            layer.set_region_weights(weights)
        return layer

    def apply(
        self,
        lam: Optional[float] = None,
        rotation_rule: Optional[str] = None,
        mask: Optional[np.ndarray] = None,
        region: RegionArg = "saved",
        feather: Optional[int] = None,
        strength: Optional[float] = None,
    ) -> np.ndarray:
        """The deformed positions (V, 3) float64, as ``stylize apply`` writes them (normalized
        frame, ``recenter_rescale``; a localized run with its saved region unless ``region`` or
        ``mask`` says otherwise). ``strength`` (≥ 1): the result at ``lam`` pushed that many times
        as far by the strength control, as ``stylize apply --strength`` (docs/strength.md);
        ``strength=1`` is the plain result."""
        layer = self.layer(lam=lam, rotation_rule=rotation_rule, mask=mask, region=region, feather=feather)
        if strength is None:
            return layer.forward(self.targets()).positions
        if not (np.isfinite(strength) and strength >= 1.0):
            raise ValueError(f"strength must be a number >= 1 (a weaker result: a smaller lam), got {strength!r}")
        return layer.forward_at_strength(self.targets(), float(strength)).positions


    @property
    def input_frame(self) -> Optional[np.ndarray]:
        """The ``to_input_frame`` key: a (4, 4) float64 homogeneous matrix ``M`` with
        ``p_input = M[:3, :3] @ q + M[:3, 3]`` for ``q`` in the frame of ``verts`` (None when the
        file does not record it, e.g. the reference's)."""
        m = self.extra.get("to_input_frame")
        if m is None:
            return None
        m = np.asarray(m, dtype=np.float64)
        if m.shape != (4, 4) or not np.all(np.isfinite(m)) or not np.array_equal(m[3], [0, 0, 0, 1]):
            raise ValueError(f"{self.path}: key `to_input_frame` must be a finite (4, 4) affine matrix")
        if np.linalg.det(m[:3, :3]) == 0.0:
            raise ValueError(f"{self.path}: key `to_input_frame` is singular")
        return m

    def to_input_frame(self, positions: np.ndarray) -> np.ndarray:
        """A result of :meth:`apply` (normalized frame, vertex centroid at the origin) placed in
        the input file's coordinates, as ``stylize apply`` writes it by default: moved back by the
        rest mesh's vertex centroid, then mapped by ``to_input_frame``. Raises ``ValueError`` when
        the file does not record its input frame."""
        m = self.input_frame
        if m is None:
            raise ValueError(f"{self.path}: the file does not record its input frame (`to_input_frame`)")
        q = np.asarray(positions, dtype=np.float64) + self.rest_positions().mean(axis=0)
        return q @ m[:3, :3].T + m[:3, 3]


def _rows3(path: str, key: str, a: np.ndarray, kind: str) -> np.ndarray:
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{path}: key `{key}` must have shape (N, 3), got {a.shape}")
    if a.dtype.kind not in kind:
        raise ValueError(f"{path}: key `{key}` has dtype {a.dtype}, expected {'a float' if kind == 'f' else 'an integer'} dtype")
    return a


def _string(path: str, key: str, a: np.ndarray) -> str:
    if a.dtype.kind not in "US" or a.size != 1:
        raise ValueError(f"{path}: key `{key}` must be a 0-d string array, got dtype {a.dtype} shape {a.shape}")
    value = a.reshape(-1)[0]
    return value.decode("utf-8") if isinstance(value, bytes) else str(value)


def load_saved(npz_path: PathLike) -> SavedDeformation:
    """Reads a saved deformation (``.npz`` in the reference's format, spec §8).

    Checks what ``stylize::saved::SavedDeformation::read`` checks: the five standard keys exist,
    ``verts``/``verts_normals`` are float (V, 3) with the same V, ``faces`` integer (F, 3) with
    indices in [0, V). Raises ``ValueError`` naming the file and key otherwise (and
    ``FileNotFoundError`` for a missing file). No pickled data is ever loaded.
    """
    path = os.fspath(npz_path)
    try:
        archive = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise
    except (ValueError, OSError) as e:
        raise ValueError(f"{path}: not a readable .npz archive ({e})") from e
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise ValueError(f"{path}: a single .npy array, not an .npz archive of a saved deformation")
    with archive:
        arrays: Dict[str, np.ndarray] = {}
        for key in archive.files:
            try:
                arrays[key] = archive[key]
            except ValueError as e:  # pickled object arrays
                raise ValueError(f"{path}: key `{key}` cannot be read ({e})") from e
    missing = [k for k in STANDARD_KEYS if k not in arrays]
    if missing:
        raise ValueError(f"{path}: missing key(s) {', '.join(f'`{k}`' for k in missing)} of a saved deformation")
    verts = _rows3(path, "verts", arrays["verts"], "f")
    verts_normals = _rows3(path, "verts_normals", arrays["verts_normals"], "f")
    faces = _rows3(path, "faces", arrays["faces"], "iu")
    if len(verts_normals) != len(verts):
        raise ValueError(f"{path}: key `verts_normals` has {len(verts_normals)} rows but `verts` has {len(verts)}")
    if faces.size:
        bad = np.flatnonzero(((faces < 0) | (faces >= len(verts))).any(axis=1))
        if bad.size:
            f = int(bad[0])
            raise ValueError(
                f"{path}: key `faces`: face {f} = {faces[f].tolist()} refers to a vertex beyond the {len(verts)} in `verts`"
            )
    return SavedDeformation(
        path=path,
        verts=verts,
        faces=faces,
        verts_normals=verts_normals,
        deform_by_csd_cfg=_string(path, "deform_by_csd_cfg", arrays["deform_by_csd_cfg"]),
        dataset_cfg=_string(path, "dataset_cfg", arrays["dataset_cfg"]),
        extra={k: v for k, v in arrays.items() if k not in STANDARD_KEYS},
    )
