"""Type stubs of the extension module ``darap._darap`` (re-exported by ``darap``)."""

from typing import Optional, Tuple

import numpy as np
import numpy.typing as npt

__version__: str

Float3 = npt.NDArray[np.floating]  # (N, 3) float64 or float32, any memory layout
Index3 = npt.NDArray[np.integer]  # (F, 3) int32/int64/uint32/uint64, 0-based, CCW
Mask = npt.NDArray[np.bool_]  # (V,) True where the vertex may rotate
Weights = npt.NDArray[np.floating]  # (V,) float64/float32 region weights in [0, 1]

class DarapError(ValueError):
    """An error reported by the Rust dARAP layer (the message is the Rust one): non-finite input,
    face index out of range, singular Laplacian, mesh without faces, …"""

class Deformation:
    """The result of :meth:`Darap.forward`: deformed positions plus the record (rotations, local
    and post-processing tapes, the raw targets and λ) that :meth:`Darap.backward` needs. Opaque;
    valid only with the layer that produced it."""

    @property
    def positions(self) -> npt.NDArray[np.float64]:
        """Deformed positions (V, 3) float64, after post-processing. The same array on every
        access; writing to it does not affect the backward pass."""
    @property
    def rotations(self) -> npt.NDArray[np.float64]:
        """Per-vertex rotations of the local step (V, 3, 3), ``R[v] @ e`` rotates a column vector
        (a new array on every access)."""
    @property
    def lam(self) -> float:
        """The λ this deformation was computed with."""

class Darap:
    """A dARAP layer for one rest mesh (spec §1–§4; conventions in ``docs/darap.md``).

    Everything λ-independent is precomputed here, with the GIL released: cotangent weights
    ``c_ij = cot α + cot β`` (twice libigl's), mixed-Voronoi masses, area-weighted rest normals,
    rest covariances, and the pinned sparse Cholesky factorization (the lowest vertex of each
    connected component is pinned at rest; vertex 0 for a connected mesh).

    ``verts`` (V, 3) float64/float32 are used **as given**: to reproduce the reference (and saved
    ``.npz`` files) normalize them to the side-2 cube first with :func:`normalize_side2_cube`.
    ``faces`` (F, 3) int32/int64/uint32/uint64, CCW. ``lam`` (λ, default 8) weighs the normal term
    against the one-ring term; ``rotation_rule`` is ``"gis"`` (the reference's, default) or
    ``"procrustes"`` (textbook Kabsch; needs a larger λ, ~40 ≈ gis 8). ``mask``: optional (V,)
    bool, True where the vertex may rotate (False forces ``R_v = I``). ``post_process``:
    ``"recenter_rescale"`` (default: centroid to the origin, bounding-box diagonal scaled to the
    rest mesh's), ``"recenter_only"`` or ``"none"``.

    Raises ``TypeError`` (not a NumPy array, wrong dtype), ``ValueError`` (wrong shape, bad option)
    and :class:`DarapError` (errors of the Rust layer, e.g. a face index out of range, non-finite
    positions, a singular Laplacian).
    """

    def __init__(
        self,
        verts: Float3,
        faces: Index3,
        lam: float = 8.0,
        rotation_rule: str = "gis",
        mask: Optional[Mask] = None,
        post_process: str = "recenter_rescale",
    ) -> None: ...
    def forward(self, x: Float3) -> Deformation:
        """Deforms the mesh toward raw target normals ``x`` (V, 3) float64/float32; only
        directions matter (``t = x / max(|x|, 1e-12)``). GIL released. Raises
        :class:`DarapError` for non-finite targets."""
    def forward_at_strength(self, x: Float3, strength: float) -> Deformation:
        """The strength control (docs/strength.md): :meth:`forward` at this layer's λ pushed
        ``strength`` times as far by the ``procrustes`` rule's increment,
        ``R_v(s) = P_v(s·λ)·P_v(λ)ᵀ·R_v(λ)``, then the global step. ``strength = 1`` is
        :meth:`forward` exactly; ≥ 1 is the intended use. The result's :meth:`backward` raises
        :class:`DarapError` unless ``strength = 1`` (no tape). Raises :class:`DarapError` for a
        non-finite or non-positive strength. GIL released."""
    def backward(self, deformation: Deformation, grad_positions: Float3) -> npt.NDArray[np.float64]:
        """The vector-Jacobian product: ∂ℓ/∂x (V, 3) for ∂ℓ/∂positions (V, 3), at a
        deformation computed by this layer's :meth:`forward` (with the λ, rule and mask of that
        call). GIL released."""
    def rest_normals(self) -> npt.NDArray[np.float64]:
        """Area-weighted rest vertex normals (V, 3): the initial ``x`` of an optimization."""
    def rest_positions(self) -> npt.NDArray[np.float64]:
        """The rest positions as given (V, 3) float64."""
    def mass(self) -> npt.NDArray[np.float64]:
        """Mixed-Voronoi vertex areas ``a_v`` (V,)."""
    def pins(self) -> npt.NDArray[np.int64]:
        """Pinned vertices (sorted): the lowest vertex of each connected component."""
    def set_lambda(self, lam: float) -> None:
        """Changes λ (O(1); nothing is recomputed). Must be finite."""
    def set_rotation_rule(self, rotation_rule: str) -> None:
        """``"gis"`` or ``"procrustes"`` (nothing is recomputed)."""
    def set_post_process(self, post_process: str) -> None:
        """``"recenter_rescale"``, ``"recenter_only"`` or ``"none"``."""
    def set_mask(self, mask: Optional[Mask]) -> None:
        """(V,) bool, True where the vertex may rotate; ``None`` lets every vertex rotate."""
    def set_region_weights(self, weights: Optional[Weights]) -> None:
        """A feathered region: (V,) weights in [0, 1] scaling λ per vertex (0 = masked, R = I;
        1 = free), as ``stylize apply`` uses; ``None`` lets every vertex rotate. Replaces any
        mask."""
    def region_weights(self) -> Optional[npt.NDArray[np.float64]]:
        """(V,) weights (1 free, 0 masked, feather in between), ``None`` when all may rotate."""
    @property
    def lam(self) -> float: ...
    @property
    def rotation_rule(self) -> str: ...
    @property
    def post_process(self) -> str: ...
    @property
    def num_vertices(self) -> int: ...

def normalize_side2_cube(
    verts: Float3,
) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], float]:
    """Side-2 cube normalization (spec §1.1, ``mesh_core::normalize::side2_cube``), in float64:
    ``p' = (p − centre) · scale`` with ``centre`` the bounding-box centre and
    ``scale = 2 / (largest bbox extent)``. The longest side becomes [−1, 1]; the vertex centroid
    is not subtracted. A degenerate input is only centred (scale 1). Returns
    ``(normalized (V, 3), centre (3,), scale)``."""

def icosphere(level: int) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """A unit icosphere subdivided ``level`` times (0 ≤ level ≤ 7; level 3 has 642 vertices):
    ``(verts (V, 3) float64, faces (F, 3) int64)``."""

def feather_weights(free: Mask, faces: Index3, rings: int) -> npt.NDArray[np.float64]:
    """Feathered region weights (``mesh_core::region::feather_weights``, what ``stylize run
    --region-feather`` and ``stylize apply`` use): a vertex at edge-hop distance ``d`` from the
    nearest vertex outside the region (``free`` False) gets ``min(d / (rings + 1), 1)``; outside
    vertices get 0. Returns (V,) float64."""

def self_intersections(positions: Float3, faces: Index3) -> npt.NDArray[np.int64]:
    """Exact self-intersections (``mesh_core::intersect``, what ``stylize mesh check``, ``eval``
    and ``apply`` count; definitions in ``docs/self_intersections.md``). Returns the intersecting
    face pairs (K, 2) int64, each row ``(a, b)`` with ``a < b``, rows sorted. Raises
    :class:`DarapError` for no faces, an index out of range or a non-finite vertex used by a
    face."""
