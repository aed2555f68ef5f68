"""The PyTorch wrapper (runs only where torch is importable; skipped otherwise)."""

from __future__ import annotations

import numpy as np
import pytest

import darap

torch = pytest.importorskip("torch")
from darap.torch import DarapFunction, DarapLayer  # noqa: E402


def small_problem(level: int = 1, seed: int = 3, **kwargs):
    verts, faces = darap.icosphere(level)
    layer = DarapLayer(torch.from_numpy(verts), torch.from_numpy(faces), **kwargs)
    g = torch.Generator().manual_seed(seed)
    x = layer.rest_normals() + 0.3 * torch.randn(len(verts), 3, generator=g, dtype=torch.float64)
    return layer, x


@pytest.mark.parametrize("rule,lam", [("gis", 8.0), ("procrustes", 40.0)])
def test_gradcheck_float64(rule: str, lam: float) -> None:
    layer, x = small_problem(rotation_rule=rule, lam=lam)
    x.requires_grad_(True)
    assert torch.autograd.gradcheck(lambda t: DarapFunction.apply(t, layer.darap), (x,), eps=1e-6, atol=1e-6, rtol=1e-5)


def test_module_matches_the_numpy_layer() -> None:
    layer, x = small_problem(level=2)
    x.requires_grad_(True)
    positions = layer(x)
    cotangent = torch.randn_like(positions)
    (positions * cotangent).sum().backward()
    out = layer.darap.forward(x.detach().numpy())
    np.testing.assert_array_equal(positions.detach().numpy(), out.positions)
    np.testing.assert_array_equal(x.grad.numpy(), layer.darap.backward(out, cotangent.numpy()))


def test_float32_in_float32_out() -> None:
    layer, x = small_problem()
    x32 = x.float().requires_grad_(True)
    positions = layer(x32)
    assert positions.dtype == torch.float32
    positions.square().sum().backward()
    assert x32.grad is not None and x32.grad.dtype == torch.float32


def test_adam_on_target_normals_lowers_an_image_free_objective() -> None:
    """The docs/python.md example in miniature: push the deformed sphere's normals toward ±z."""
    verts, faces = darap.icosphere(2)
    layer = DarapLayer(verts, faces, lam=8.0)
    faces_t = torch.from_numpy(faces)
    x = layer.rest_normals().clone().requires_grad_(True)
    opt = torch.optim.Adam([x], lr=0.05)

    def objective() -> torch.Tensor:
        p = layer(x)
        n = torch.cross(p[faces_t[:, 1]] - p[faces_t[:, 0]], p[faces_t[:, 2]] - p[faces_t[:, 0]], dim=1)
        n = n / n.norm(dim=1, keepdim=True)
        return -(n[:, 2] ** 4).mean()  # favour faces looking up or down

    first = objective().item()
    for _ in range(20):
        opt.zero_grad()
        loss = objective()
        loss.backward()
        opt.step()
    assert objective().item() < first - 1e-3


def test_wrong_layer_type_raises() -> None:
    _, x = small_problem()
    with pytest.raises(TypeError, match="layer must be a darap.Darap"):
        DarapFunction.apply(x, "not a layer")
