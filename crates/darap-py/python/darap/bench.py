"""``python -m darap.bench``: forward and backward times of the Python layer on the fixture meshes.

Meshes: the golden bunny (1,839 V), CGAL's cow (2,904 V) and fandisk (6,475 V) from the
repository's ``fixtures/`` (found from the current directory upward, or ``--fixtures DIR``), each
normalized to the side-2 cube, and icospheres of 10,242 and 40,962 vertices. Prints a Markdown
table of median wall times (ms) over ``--reps`` calls, including the NumPy conversions, so the
numbers compare with ``cargo run --release -p darap --example bench_darap``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Callable, List, Optional, Tuple

import numpy as np

from ._darap import Darap, icosphere, normalize_side2_cube

Mesh = Tuple[np.ndarray, np.ndarray]


def read_obj(path: Path) -> Mesh:
    verts, faces = [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if parts and parts[0] == "v":
            verts.append([float(c) for c in parts[1:4]])
        elif parts and parts[0] == "f":
            idx = [int(p.split("/")[0]) for p in parts[1:]]
            idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
            faces.extend([idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1))
    return np.array(verts, dtype=np.float64), np.array(faces, dtype=np.int64)


def read_off(path: Path) -> Mesh:
    tokens = []
    for line in path.read_text().splitlines():
        tokens.extend(line.split("#", 1)[0].split())
    if not tokens or not tokens[0].endswith("OFF"):
        raise ValueError(f"{path}: not an ASCII OFF file")
    nv, nf = int(tokens[1]), int(tokens[2])
    pos = 4
    verts = np.array(tokens[pos : pos + 3 * nv], dtype=np.float64).reshape(nv, 3)
    pos += 3 * nv
    faces = []
    for _ in range(nf):
        k = int(tokens[pos])
        idx = [int(t) for t in tokens[pos + 1 : pos + 1 + k]]
        faces.extend([idx[0], idx[j], idx[j + 1]] for j in range(1, k - 1))
        pos += 1 + k
    return verts, np.array(faces, dtype=np.int64)


def find_fixtures(start: Path) -> Optional[Path]:
    for d in [start, *start.parents]:
        if (d / "fixtures" / "meshes").is_dir():
            return d / "fixtures"
    return None


def median_ms(f: Callable[[], object], reps: int) -> float:
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        f()
        times.append((time.perf_counter() - t0) * 1e3)
    return float(np.median(times))


def meshes(fixtures: Optional[Path], max_vertices: int) -> List[Tuple[str, Mesh]]:
    out: List[Tuple[str, Mesh]] = []
    if fixtures is not None:
        sources = [
            ("bunny", fixtures / "golden" / "bunny.obj", read_obj),
            ("cow", fixtures / "meshes" / "cow.off", read_off),
            ("fandisk", fixtures / "meshes" / "fandisk.off", read_off),
        ]
        for name, path, reader in sources:
            if path.is_file():
                verts, faces = reader(path)
                out.append((name, (normalize_side2_cube(verts)[0], faces)))
    for level in (5, 6):
        out.append((f"icosphere/{level}", icosphere(level)))
    return [(n, m) for n, m in out if len(m[0]) <= max_vertices]


def main(argv: Optional[List[str]] = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m darap.bench", description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=11, help="calls per measurement (median)")
    ap.add_argument("--max-vertices", type=int, default=50_000)
    ap.add_argument("--fixtures", type=Path, default=None, help="the repository's fixtures/ folder")
    args = ap.parse_args(argv)
    fixtures = args.fixtures or find_fixtures(Path.cwd())
    if fixtures is None:
        print("(no fixtures/ folder found from here upward: icospheres only; pass --fixtures DIR)")
    reps = max(args.reps, 1)
    rng = np.random.default_rng(0)
    print("| mesh | V | precompute ms | forward ms | backward ms | fwd+bwd ms |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, (verts, faces) in meshes(fixtures, args.max_vertices):
        pre = median_ms(lambda: Darap(verts, faces), max(1, min(reps, 3)))
        layer = Darap(verts, faces)
        x = layer.rest_normals() + 0.3 * rng.standard_normal(verts.shape)
        g = rng.standard_normal(verts.shape)
        out = layer.forward(x)
        fwd = median_ms(lambda: layer.forward(x), reps)
        bwd = median_ms(lambda: layer.backward(out, g), reps)
        both = median_ms(lambda: layer.backward(layer.forward(x), g), reps)
        print(f"| {name} | {len(verts)} | {pre:.1f} | {fwd:.2f} | {bwd:.2f} | {both:.2f} |", flush=True)


if __name__ == "__main__":
    main()
