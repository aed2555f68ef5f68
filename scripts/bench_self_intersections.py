#!/usr/bin/env python3
"""Self-intersection check: ours (mesh_core::intersect) against pymeshlab's
`compute_selection_by_self_intersections_per_face`, on the same f32-rounded meshes, face by face.

pymeshlab is GPL: it is never a dependency of the project. Install it in a benchmark venv outside
the repository:

    python3 -m venv /work/venvs/pymeshlab && /work/venvs/pymeshlab/bin/pip install pymeshlab numpy
    cargo build --release -p mesh-core --features io --example self_intersection_bench
    /work/venvs/pymeshlab/bin/python scripts/bench_self_intersections.py OUT_DIR [--rounds N] [MESH...]

Each of N rounds (default 3) runs our example once (which writes OUT_DIR/NAME.obj and
NAME.faces.txt and prints our timings for every mesh), then times pymeshlab on each NAME.obj in
this process's CPU time (descheduled time does not count; repeated until >= 0.3 s of CPU). The
rounds alternate the two tools, so a slow spell of the (shared, virtual) machine falls on both.
Both run on one core (`taskset -c 0`).

It prints a Markdown table: faces, our pairs/faces, pymeshlab's faces, faces only we report /
only pymeshlab reports, then the CPU ms per call of each, each the **minimum over the rounds**
(the least disturbed measurement; ours: one full check on a built tree, the BVH build, and the
refit + check; pymeshlab builds its grid in every call), the ratios of those minima for our
check alone and for our BVH build + check, the ratio of the two tools' medians over the rounds
(build + check: the typical run), and the range of the build + check ratio over the rounds (each
round's own pymeshlab / ours), which shows how far one run can move it.
"""

import os
import statistics
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
    args = sys.argv[1:]
    rounds = 3
    if "--rounds" in args:
        i = args.index("--rounds")
        rounds = int(args[i + 1])
        del args[i:i + 2]
    if not args or rounds < 1:
        sys.exit(__doc__)
    out, extra = args[0], args[1:]
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    exe = os.path.join(root, "target/release/examples/self_intersection_bench")
    os.sched_setaffinity(0, {0})
    # Per mesh: lists over the rounds of our (check, build, refit + check) and pymeshlab's ms.
    ours, theirs, info, names = {}, {}, {}, []
    for r in range(rounds):
        text = subprocess.run(["taskset", "-c", "0", exe, out, *extra], check=True,
                              capture_output=True, text=True).stdout
        lines = [l.split("\t") for l in text.strip().splitlines()]
        head = lines[0]
        for row in lines[1:]:
            d = dict(zip(head, row))
            name = d["mesh"]
            if r == 0:
                names.append(name)
                info[name] = d
            ours.setdefault(name, []).append(
                (float(d["check_cpu_ms"]), float(d["build_cpu_ms"]),
                 float(d["refit_check_cpu_ms"])))
        for name in names:
            ms = pymeshlab.MeshSet()
            ms.load_new_mesh(os.path.join(out, name + ".obj"))
            m = ms.current_mesh()
            assert m.face_number() == int(info[name]["faces"]), name

            def run():
                ms.compute_selection_by_self_intersections_per_face()

            theirs.setdefault(name, []).append(timed(run))
            if r == 0:
                sel = ms.current_mesh().face_selection_array()
                info[name]["theirs"] = {i for i, s in enumerate(sel) if s}
        print("round %d of %d done" % (r + 1, rounds), file=sys.stderr)
    print("| mesh | faces | our pairs | our faces | pymeshlab faces | only ours | only pymeshlab "
          "| ours: check CPU ms | ours: build CPU ms | ours: refit + check CPU ms "
          "| pymeshlab CPU ms | pymeshlab / ours (check) | pymeshlab / ours (build + check) "
          "| build + check ratio of the medians | build + check ratio, range over rounds |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name in names:
        d = info[name]
        theirs_faces = d["theirs"]
        with open(os.path.join(out, name + ".faces.txt")) as f:
            mine = {int(l) for l in f if l.strip()}
        only_ours = sorted(mine - theirs_faces)
        only_theirs = sorted(theirs_faces - mine)
        with open(os.path.join(out, name + ".diff.txt"), "w") as f:
            f.write("only ours: %s\nonly pymeshlab: %s\n" % (only_ours, only_theirs))
        check = min(o[0] for o in ours[name])
        build = min(o[1] for o in ours[name])
        refit = min(o[2] for o in ours[name])
        t = min(theirs[name])
        per_round = [p / max(o[1] + o[0], 1e-9) for o, p in zip(ours[name], theirs[name])]
        medians = statistics.median(theirs[name]) / max(
            statistics.median(o[1] + o[0] for o in ours[name]), 1e-9)
        print("| %s | %s | %s | %s | %d | %d | %d | %.2f | %.2f | %.2f | %.1f | %.1f× | %.1f× "
              "| %.1f× | %.1f–%.1f× |" % (
                  name, d["faces"], d["pairs"], d["faces_involved"], len(theirs_faces),
                  len(only_ours), len(only_theirs), check, build, refit, t,
                  t / max(check, 1e-9), t / max(build + check, 1e-9), medians,
                  min(per_round), max(per_round)))


if __name__ == "__main__":
    main()
