//! Self-intersection check timings and face lists, for the side-by-side comparison with
//! pymeshlab (`scripts/bench_self_intersections.py`, docs/benchmarks.md).
//!
//! `cargo run --release -p mesh-core --features io --example self_intersection_bench -- OUT_DIR
//! [MESH…] [--reps N] [--only NAME]`
//!
//! Writes into `OUT_DIR`, for each mesh: `NAME.obj` (coordinates rounded to f32, which MeshLab
//! stores, so both tools see the same numbers), `NAME.faces.txt` (our intersecting faces, one
//! index per line) and `NAME.pairs.txt` (our intersecting pairs `a b`, one per line, sorted), and prints one tab-separated line per mesh: name, faces, pairs, faces
//! involved, candidates, then per call: BVH build, one full check, refit + check (the viewer's
//! per-move cost) in **CPU ms of the thread** (the machine is shared: descheduled time does not
//! count; each repeated until ≥ 0.3 s of CPU and ≥ N times), the check's wall ms, the BVH's
//! self-overlap traversal alone (CPU ms) and the check on 2 threads (`set_threads(2)`, wall ms:
//! the viewer's setting). Meshes: the fixtures eight (634 faces), bunny, fandisk and
//! cow, the bunny midpoint-subdivided ×1, ×2, ×3 (up to 235k faces), the cow ×2 (46,434
//! vertices: the viewer's latency mesh, `stylize-cli/examples/view_latency.rs`) and a torus of 200k faces,
//! then any MESH given (e.g. stylized results). `--only NAME` runs one of them (for profiling).

#![allow(clippy::unwrap_used)]

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use mesh_core::TriMesh;
use mesh_core::intersect::SelfIntersectionChecker;

fn torus(nu: usize, nv: usize) -> TriMesh {
    let (r0, r1) = (1.0, 0.35);
    let mut positions = Vec::new();
    for i in 0..nu {
        let u = std::f64::consts::TAU * i as f64 / nu as f64;
        for j in 0..nv {
            let v = std::f64::consts::TAU * j as f64 / nv as f64;
            positions.push([
                (r0 + r1 * v.cos()) * u.cos(),
                (r0 + r1 * v.cos()) * u.sin(),
                r1 * v.sin(),
            ]);
        }
    }
    let id = |i: usize, j: usize| ((i % nu) * nv + (j % nv)) as u32;
    let mut faces = Vec::new();
    for i in 0..nu {
        for j in 0..nv {
            faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    TriMesh::new(positions, faces)
}

/// CPU time of this thread in ms (`/proc/thread-self/stat` utime + stime, 10 ms ticks): on a
/// machine shared with other work, time the thread was descheduled does not count.
fn thread_cpu_ms() -> f64 {
    let stat = std::fs::read_to_string("/proc/thread-self/stat").unwrap();
    // Fields after the command name (which is in parentheses and may hold spaces).
    let rest = &stat[stat.rfind(')').unwrap() + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f[11].parse::<f64>().unwrap() + f[12].parse::<f64>().unwrap();
    ticks * 10.0
}

/// Runs `f` at least `min_reps` times and until it has used ≥ 0.3 s of CPU; returns
/// (CPU ms per call, wall ms per call).
fn timed(min_reps: usize, mut f: impl FnMut()) -> (f64, f64) {
    let (c0, t0) = (thread_cpu_ms(), Instant::now());
    let mut n = 0usize;
    while n < min_reps || thread_cpu_ms() - c0 < 300.0 {
        f();
        n += 1;
    }
    (
        (thread_cpu_ms() - c0) / n as f64,
        t0.elapsed().as_secs_f64() * 1e3 / n as f64,
    )
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut reps = 5usize;
    if let Some(i) = args.iter().position(|a| a == "--reps") {
        reps = args[i + 1].parse().unwrap();
        args.drain(i..i + 2);
    }
    let mut only: Option<String> = None;
    if let Some(i) = args.iter().position(|a| a == "--only") {
        only = Some(args[i + 1].clone());
        args.drain(i..i + 2);
    }
    let out = PathBuf::from(args.first().expect("OUT_DIR"));
    std::fs::create_dir_all(&out).unwrap();
    let fixtures = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/meshes");
    let read = |p: &Path| mesh_core::io::read_mesh(p).unwrap();
    let bunny = read(&fixtures.join("bunny.obj"));
    let sub = |m: &TriMesh, k: usize| {
        let mut m = m.clone();
        for _ in 0..k {
            m = mesh_core::subdivide::midpoint(&m);
        }
        m
    };
    let mut meshes: Vec<(String, TriMesh)> = vec![
        ("eight".into(), read(&fixtures.join("eight.off"))),
        ("bunny".into(), bunny.clone()),
        ("cow".into(), read(&fixtures.join("cow.off"))),
        ("fandisk".into(), read(&fixtures.join("fandisk.off"))),
        ("bunny_x1".into(), sub(&bunny, 1)),
        ("bunny_x2".into(), sub(&bunny, 2)),
        ("cow_x2".into(), sub(&read(&fixtures.join("cow.off")), 2)),
        ("torus_200k".into(), torus(500, 200)),
        ("bunny_x3".into(), sub(&bunny, 3)),
    ];
    for extra in &args[1..] {
        let p = PathBuf::from(extra);
        let name = p.file_stem().unwrap().to_string_lossy().into_owned();
        meshes.push((name, read(&p)));
    }
    println!(
        "mesh\tfaces\tpairs\tfaces_involved\tcandidates\tbuild_cpu_ms\tcheck_cpu_ms\trefit_check_cpu_ms\tcheck_wall_ms\ttraversal_cpu_ms\tcheck_2_threads_wall_ms"
    );
    for (name, mut mesh) in meshes {
        if only.as_ref().is_some_and(|o| *o != name) {
            continue;
        }
        for p in &mut mesh.positions {
            *p = p.map(|c| f64::from(c as f32));
        }
        mesh_core::io::write_mesh(out.join(format!("{name}.obj")), &mesh, None).unwrap();
        let (build, _) = timed(1, || {
            SelfIntersectionChecker::new(&mesh.positions, &mesh.faces).unwrap();
        });
        let mut checker = SelfIntersectionChecker::new(&mesh.positions, &mesh.faces).unwrap();
        let r = checker.check();
        let (check, check_wall) = timed(reps, || {
            checker.check();
        });
        let (refit, _) = timed(reps, || {
            checker.check_moved(&mesh.positions).unwrap();
        });
        checker.set_threads(2);
        let (_, check2_wall) = timed(reps, || {
            checker.check();
        });
        checker.set_threads(1);
        let bvh = mesh_core::bvh::Bvh::new(&mesh.positions, &mesh.faces).unwrap();
        let (traversal, _) = timed(reps, || {
            let mut n = 0usize;
            bvh.for_each_overlapping_pair(|_, _| n += 1);
            std::hint::black_box(n);
        });
        let mut f = std::fs::File::create(out.join(format!("{name}.faces.txt"))).unwrap();
        for face in &r.faces {
            writeln!(f, "{face}").unwrap();
        }
        let mut f = std::fs::File::create(out.join(format!("{name}.pairs.txt"))).unwrap();
        for (a, b) in &r.pairs {
            writeln!(f, "{a} {b}").unwrap();
        }
        println!(
            "{name}\t{}\t{}\t{}\t{}\t{build:.2}\t{check:.2}\t{refit:.2}\t{check_wall:.1}\t{traversal:.1}\t{check2_wall:.1}",
            mesh.faces.len(),
            r.pairs.len(),
            r.faces.len(),
            r.candidates,
        );
    }
}
