#!/usr/bin/env python3
"""Side-by-side benchmark: our isotropic remesher (`mesh_core::remesh`, the one `stylize remesh`
and `stylize run --remesh` call) against pymeshlab's `meshing_isotropic_explicit_remeshing`, same
target edge length (a percentage of the bounding-box diagonal), iteration count and feature angle,
one mesh at a time, both tools back to back.

pymeshlab is GPL: it is NEVER a dependency of this project. Install it in a venv outside the
repository, e.g.

    python3 -m venv /work/venvs/remesh-pml && /work/venvs/remesh-pml/bin/pip install pymeshlab numpy
    cargo build --release -p mesh-core --example remesh_file
    bash scripts/fetch-meshes.sh
    taskset -c 0 /work/venvs/remesh-pml/bin/python scripts/bench_remesh.py [--iterations 10] [--percent 1.5]

Both tools run on one core (`taskset -c 0` pins this process — pymeshlab — and our measuring
binary, a child that inherits the affinity; OMP_NUM_THREADS=1). Quality of both outputs is
measured by the same code, `crates/mesh-core/examples/remesh_file.rs` (edge std/mean, minimum
angle, share of faces with a corner under 10°, sampled two-sided Hausdorff distance to the input
as % of the bounding-box diagonal, exact self-intersecting face pairs of the input and of the
output): ours on its own output, and with ITERATIONS 0 and a REFERENCE
on pymeshlab's output against the input. Time is wall time of the remeshing call alone (ours:
around `remesh()`; pymeshlab: around the filter call), excluding file reading and writing.

Prints a Markdown table (docs/benchmarks.md, "Isotropic remeshing").
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MESHES = [
    "fixtures/meshes/external/rotor.off",
    "fixtures/meshes/bunny.obj",
    "fixtures/meshes/external/rotor_small.off",
    "fixtures/meshes/triceratops.off",
    "fixtures/meshes/cow.off",
    "fixtures/meshes/external/anchor_dense.off",
    "fixtures/meshes/external/bull.off",
    "fixtures/meshes/fandisk.off",
    "fixtures/meshes/external/turbine.off",
    "fixtures/meshes/external/camel.off",
    "fixtures/meshes/external/mannequin-devil.off",
    "fixtures/meshes/external/armadillo.off",
    "fixtures/meshes/external/bunny00.off",
    "fixtures/meshes/external/refined_elephant.off",
    "fixtures/meshes/external/bunny00_x4.off",
]


def ours(binary, mesh, out, args):
    r = subprocess.run(
        [binary, str(mesh), str(out), *args],
        check=True,
        capture_output=True,
        text=True,
        env={**os.environ, "OMP_NUM_THREADS": "1", "RAYON_NUM_THREADS": "1"},
    )
    return json.loads(r.stdout)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--iterations", type=int, default=10)
    ap.add_argument("--percent", type=float, default=1.5)
    ap.add_argument("--feature-angle", type=float, default=30.0)
    ap.add_argument("--binary", default=str(ROOT / "target/release/examples/remesh_file"))
    ap.add_argument("meshes", nargs="*")
    a = ap.parse_args()
    import pymeshlab

    meshes = [Path(m) for m in (a.meshes or [ROOT / m for m in MESHES])]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for mesh in meshes:
            if not mesh.exists():
                print(f"skipping {mesh}: not found (scripts/fetch-meshes.sh)", file=sys.stderr)
                continue
            o = ours(
                a.binary,
                mesh,
                tmp / "ours.obj",
                [str(a.percent), str(a.iterations), str(a.feature_angle)],
            )
            ms = pymeshlab.MeshSet()
            ms.load_new_mesh(str(mesh))
            t = time.perf_counter()
            ms.meshing_isotropic_explicit_remeshing(
                iterations=a.iterations,
                targetlen=pymeshlab.PercentageValue(a.percent),
                featuredeg=a.feature_angle,
            )
            t_pml = time.perf_counter() - t
            ms.save_current_mesh(str(tmp / "pml.obj"))
            # Measure pymeshlab's output with our code: its figures, and its distance to the input.
            m = ours(
                a.binary,
                tmp / "pml.obj",
                tmp / "pml_measured.obj",
                [str(a.percent), "0", str(a.feature_angle), str(mesh)],
            )
            rows.append((mesh.name, o, m, t_pml))
            print(f"done {mesh.name}", file=sys.stderr)
    print(
        "| mesh | faces in | tool | faces out | edge std/mean | min angle | corners < 10° "
        "| Hausdorff out→in / in→out (% diag) | self-intersecting pairs in → out | time (s) |"
    )
    print("|---|---:|---|---:|---:|---:|---:|---|---:|---:|")
    for name, o, m, t_pml in rows:
        b = o["before"]
        for tool, r, hd, secs in [
            ("ours", o["after"], o, o["seconds"]),
            ("pymeshlab", m["before"], m, t_pml),
        ]:
            print(
                f"| {name} | {b['faces']:,} | {tool} | {r['faces']:,} | "
                f"{r['edge_std_over_mean']:.3f} | {r['min_angle_deg']:.2f}° | "
                f"{100 * r['share_below_10_deg']:.2f} % | "
                f"{hd['hausdorff_out_to_in_percent_of_diagonal']:.3f} / "
                f"{hd['hausdorff_in_to_out_percent_of_diagonal']:.3f} | "
                f"{hd['self_intersecting_pairs_in']:,} → {hd['self_intersecting_pairs_out']:,} | "
                f"{secs:.3f} |"
            )


if __name__ == "__main__":
    main()
