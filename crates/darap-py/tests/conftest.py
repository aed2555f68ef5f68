"""Shared helpers of the darap Python tests (paths into the repository's fixtures)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[3]
GOLDEN = REPO / "fixtures" / "golden"
MESHES = REPO / "fixtures" / "meshes"

# (golden OBJ stem, λ, rotation rule): fixtures/golden/README.md
GOLDEN_CASES = [
    ("bunny_lambda8_gis", 8.0, "gis"),
    ("bunny_lambda5_gis", 5.0, "gis"),
    ("bunny_lambda8_procrustes", 8.0, "procrustes"),
    ("bunny_lambda40_procrustes", 40.0, "procrustes"),
]


def read_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Positions (float64) and triangles (int64, 0-based) of a plain OBJ file."""
    verts, faces = [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            verts.append([float(c) for c in parts[1:4]])
        elif parts[0] == "f":
            faces.append([int(p.split("/")[0]) - 1 for p in parts[1:4]])
    return np.array(verts, dtype=np.float64), np.array(faces, dtype=np.int64)


@pytest.fixture(scope="session")
def golden_npz() -> Path:
    return GOLDEN / "bunny_targets.npz"


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20250611)
