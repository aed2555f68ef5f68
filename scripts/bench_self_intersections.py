#!/usr/bin/env python3
"""Self-intersection check: ours (mesh_core::intersect) against pymeshlab's
`compute_selection_by_self_intersections_per_face`, on the same f32-rounded meshes, face by face.

pymeshlab is GPL: it is never a dependency of the project. Install it in a benchmark venv outside
the repository:

    python3 -m venv /work/venvs/pymeshlab && /work/venvs/pymeshlab/bin/pip install pymeshlab numpy
    cargo build --release -p mesh-core --features io --example self_intersection_bench
    /work/venvs/pymeshlab/bin/python scripts/bench_self_intersections.py OUT_DIR [MESH...]

It runs our example (which writes OUT_DIR/NAME.obj and NAME.faces.txt and prints our timings),
then times pymeshlab on each NAME.obj in this process's CPU time (the machine may be shared:
descheduled time does not count; repeated until >= 0.3 s of CPU), and prints a Markdown table:
faces, our pairs/faces, pymeshlab's faces, faces only we report / only pymeshlab reports, and
the CPU ms per check of each (ours: one full check on a built tree; the BVH build and the
refit + check are in the example's output), and the ratio both for our check alone and for our
BVH build + check (pymeshlab builds its grid in every call). Both run on one core (`taskset -c 0`).
"""

import os
import subprocess
import sys
import time

import pymeshlab


def timed(f, min_reps=1, min_cpu=0.3):
    c0 = time.process_time()
    n = 0
    while n < min_reps or time.process_time() - c0 < min_cpu:
        f()
        n += 1
    return (time.process_time() - c0) / n * 1e3


def main():
    out = sys.argv[1]
    extra = sys.argv[2:]
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    exe = os.path.join(root, "target/release/examples/self_intersection_bench")
    ours = subprocess.run(["taskset", "-c", "0", exe, out, *extra], check=True,
                          capture_output=True, text=True).stdout
    os.sched_setaffinity(0, {0})
    rows = [l.split("\t") for l in ours.strip().splitlines()]
    head, rows = rows[0], rows[1:]
    print("| mesh | faces | our pairs | our faces | pymeshlab faces | only ours | only pymeshlab "
          "| ours: check CPU ms | ours: build CPU ms | ours: refit + check CPU ms "
          "| pymeshlab CPU ms | pymeshlab / ours (check) | pymeshlab / ours (build + check) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        d = dict(zip(head, r))
        name = d["mesh"]
        ms = pymeshlab.MeshSet()
        ms.load_new_mesh(os.path.join(out, name + ".obj"))
        m = ms.current_mesh()
        assert m.face_number() == int(d["faces"]), (name, m.face_number(), d["faces"])

        def run():
            ms.compute_selection_by_self_intersections_per_face()

        theirs_ms = timed(run)
        sel = ms.current_mesh().face_selection_array()
        theirs = {i for i, s in enumerate(sel) if s}
        with open(os.path.join(out, name + ".faces.txt")) as f:
            mine = {int(l) for l in f if l.strip()}
        only_ours = sorted(mine - theirs)
        only_theirs = sorted(theirs - mine)
        with open(os.path.join(out, name + ".diff.txt"), "w") as f:
            f.write("only ours: %s\nonly pymeshlab: %s\n" % (only_ours, only_theirs))
        check = float(d["check_cpu_ms"])
        build = float(d["build_cpu_ms"])
        print("| %s | %s | %s | %s | %d | %d | %d | %.1f | %.1f | %.1f | %.1f | %.1f× | %.1f× |" % (
            name, d["faces"], d["pairs"], d["faces_involved"], len(theirs), len(only_ours),
            len(only_theirs), check, build, float(d["refit_check_cpu_ms"]),
            theirs_ms, theirs_ms / max(check, 1e-9), theirs_ms / max(build + check, 1e-9)))


if __name__ == "__main__":
    main()
