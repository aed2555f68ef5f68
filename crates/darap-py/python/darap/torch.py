"""PyTorch wrapper of the dARAP layer: ``positions = DarapLayer(verts, faces)(x)`` with autograd.

Pure Python on top of :class:`darap.Darap`; needs ``torch`` (imported here, never by
``import darap``). The forward and backward run in Rust on the CPU in float64: inputs on another
device or dtype are copied to CPU float64 and results are returned on the input's device and dtype
(so ``torch.autograd.gradcheck`` in float64 sees the exact analytic gradient).
"""

from __future__ import annotations

from typing import Any, Optional, Tuple

try:
    import torch
except ImportError as e:  # pragma: no cover - exercised only where torch is absent
    raise ImportError(
        "darap.torch needs PyTorch (`pip install torch`); the NumPy API `darap.Darap` works without it"
    ) from e

import numpy as np

from ._darap import Darap

__all__ = ["DarapFunction", "DarapLayer"]


def _to_numpy(t: torch.Tensor) -> np.ndarray:
    return t.detach().to(device="cpu", dtype=torch.float64).contiguous().numpy()


class DarapFunction(torch.autograd.Function):
    """``DarapFunction.apply(x, layer) -> positions``: the dARAP forward with its exact VJP.

    ``x`` is a (V, 3) tensor of raw target normals (only directions matter); ``layer`` a
    :class:`darap.Darap`. Returns the deformed positions (V, 3) on ``x``'s device and dtype. The
    layer's λ, rotation rule and mask at the time of the call are the ones differentiated.
    Not twice differentiable (the backward is a hand-written adjoint).
    """

    @staticmethod
    def forward(ctx: Any, x: torch.Tensor, layer: Darap) -> torch.Tensor:  # type: ignore[override]
        if not isinstance(layer, Darap):
            raise TypeError(f"layer must be a darap.Darap, got {type(layer).__name__}")
        deformation = layer.forward(_to_numpy(x))
        ctx.layer = layer
        ctx.deformation = deformation
        ctx.x_dtype = x.dtype
        ctx.x_device = x.device
        out = torch.from_numpy(np.array(deformation.positions, copy=True))
        return out.to(device=x.device, dtype=x.dtype)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx: Any, grad_positions: torch.Tensor) -> Tuple[Optional[torch.Tensor], None]:  # type: ignore[override]
        if not ctx.needs_input_grad[0]:
            return None, None
        grad_x = ctx.layer.backward(ctx.deformation, _to_numpy(grad_positions))
        return torch.from_numpy(grad_x).to(device=ctx.x_device, dtype=ctx.x_dtype), None


class DarapLayer(torch.nn.Module):
    """A ``torch.nn.Module`` around one :class:`darap.Darap` (precomputed once, here).

    ``verts``/``faces`` may be tensors or NumPy arrays; positions are used as given (normalize to
    the side-2 cube first, :func:`darap.normalize_side2_cube`, to match the reference). Calling the
    module maps target normals ``x`` (V, 3) to deformed positions (V, 3), differentiably in ``x``.
    The module has no parameters: optimize ``x`` (start from :meth:`rest_normals`).
    """

    def __init__(
        self,
        verts: Any,
        faces: Any,
        lam: float = 8.0,
        rotation_rule: str = "gis",
        mask: Any = None,
        post_process: str = "recenter_rescale",
    ) -> None:
        super().__init__()
        self.darap = Darap(
            _as_numpy(verts, np.float64),
            _as_numpy(faces, np.int64),
            lam=lam,
            rotation_rule=rotation_rule,
            mask=None if mask is None else _as_numpy(mask, np.bool_),
            post_process=post_process,
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return DarapFunction.apply(x, self.darap)

    def rest_normals(self, dtype: torch.dtype = torch.float64, device: Any = None) -> torch.Tensor:
        """Rest vertex normals (area weighted): the usual initial ``x``."""
        return torch.from_numpy(self.darap.rest_normals()).to(device=device, dtype=dtype)

    def set_lambda(self, lam: float) -> None:
        """Changes λ (O(1); the next forward uses it)."""
        self.darap.set_lambda(lam)

    def extra_repr(self) -> str:
        return repr(self.darap)


def _as_numpy(a: Any, dtype: Any) -> np.ndarray:
    if isinstance(a, torch.Tensor):
        a = a.detach().cpu().numpy()
    if isinstance(a, np.ndarray) and a.dtype == dtype:
        return a
    return np.asarray(a, dtype=dtype)
