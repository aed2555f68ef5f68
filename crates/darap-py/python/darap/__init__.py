"""dARAP for Python: per-vertex target normals to a deformed triangle mesh, with exact gradients.

A NumPy front end to the Rust ``darap`` crate (Geometry in Style, CVPR 2025, §1–§4 of the
project's method spec; conventions in ``docs/darap.md``, Python usage in ``docs/python.md``)::

    import darap
    verts, centre, scale = darap.normalize_side2_cube(verts)   # as the reference does
    layer = darap.Darap(verts, faces, lam=8.0, rotation_rule="gis")
    x = layer.rest_normals()              # the initial target normals
    out = layer.forward(x)                # out.positions: (V, 3) float64
    grad_x = layer.backward(out, grad_positions)

Positions are used **as given**: normalize to the side-2 cube first (:func:`normalize_side2_cube`)
to reproduce the reference and saved ``.npz`` files. The PyTorch wrapper lives in
:mod:`darap.torch` (imported on first use; needs ``torch``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ._darap import (
    Darap,
    DarapError,
    Deformation,
    __version__,
    feather_weights,
    icosphere,
    normalize_side2_cube,
    self_intersections,
)
from .saved import SavedDeformation, load_saved

if TYPE_CHECKING:  # pragma: no cover
    from . import torch as torch

__all__ = [
    "Darap",
    "DarapError",
    "Deformation",
    "SavedDeformation",
    "__version__",
    "feather_weights",
    "icosphere",
    "load_saved",
    "normalize_side2_cube",
    "self_intersections",
]


def __getattr__(name: str) -> Any:
    # `darap.torch` is imported lazily so that `import darap` never needs torch.
    if name == "torch":
        import importlib

        return importlib.import_module(".torch", __name__)
    raise AttributeError(f"module 'darap' has no attribute {name!r}")
