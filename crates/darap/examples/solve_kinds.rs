//! Why one mesh's dARAP backward can cost as much as its forward with faer's own solve: faer
//! picks a simplicial or a supernodal Cholesky factor by a flop-ratio heuristic, and its
//! supernodal solve calls dense kernels once per supernode — thousands of tiny ones on a mesh.
//!
//! For each mesh: the pinned Laplacian (vertex 0 pinned) factored by faer with AMD, forced
//! simplicial, forced supernodal and automatic; the time of one faer solve with three
//! right-hand sides (row-major, as `cotan` used to call it) and of `cotan`'s own substitution.
//!
//! `cargo run --release -p darap --example solve_kinds -- [--reps N] [MESH]...`

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholeskyRaw, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};
use std::time::Instant;

fn median_ms(mut f: impl FnMut(), reps: usize) -> f64 {
    let mut t: Vec<f64> = (0..reps)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut reps = 21;
    let mut paths = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        if a == "--reps" {
            reps = it.next().and_then(|v| v.parse().ok()).unwrap_or(reps);
        } else {
            paths.push(a.clone());
        }
    }
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../../fixtures");
    if paths.is_empty() {
        paths = vec![
            format!("{root}/golden/bunny.obj"),
            format!("{root}/meshes/cow.off"),
            format!("{root}/meshes/fandisk.off"),
        ];
    }
    println!(
        "| mesh | V | auto picks | kind | factor nnz | flops/nnz | faer solve ms | cotan solve ms |"
    );
    println!("|---|---:|---|---|---:|---:|---:|---:|");
    for path in &paths {
        let mut mesh = mesh_core::io::read_mesh(path)?;
        mesh_core::normalize::side2_cube(&mut mesh.positions);
        let n = mesh.positions.len();
        let l = cotan::laplacian(&mesh.positions, &mesh.faces)?;
        // Reduced matrix without vertex 0 (full symmetric storage).
        let mut col_ptr = vec![0usize];
        let mut row_idx = Vec::new();
        let mut vals = Vec::new();
        for v in 1..n {
            let (cols, values) = l.row(v);
            for (&j, &x) in cols.iter().zip(values) {
                if j != 0 {
                    row_idx.push(j - 1);
                    vals.push(x);
                }
            }
            col_ptr.push(row_idx.len());
        }
        let m = n - 1;
        let sym = SymbolicSparseColMatRef::new_checked(m, m, &col_ptr, None, &row_idx);
        let auto = factorize_symbolic_cholesky(
            sym,
            Side::Lower,
            SymmetricOrdering::Amd,
            CholeskySymbolicParams::default(),
        )?;
        let picks = match auto.raw() {
            SymbolicCholeskyRaw::Simplicial(_) => "simplicial",
            SymbolicCholeskyRaw::Supernodal(_) => "supernodal",
        };
        let chol = cotan::PinnedCholesky::new(&l, &[0])?;
        let rhs: Vec<[f64; 3]> = (0..m)
            .map(|i| [(i as f64).sin(), (i as f64 * 0.3).cos(), 1.0])
            .collect();
        let ours = median_ms(
            || {
                let mut x = rhs.clone();
                chol.solve_ordered_in_place(&mut x);
                std::hint::black_box(x);
            },
            reps,
        );
        for (kind, threshold) in [
            ("simplicial", SupernodalThreshold::FORCE_SIMPLICIAL),
            ("supernodal", SupernodalThreshold::FORCE_SUPERNODAL),
        ] {
            let symbolic = factorize_symbolic_cholesky(
                sym,
                Side::Lower,
                SymmetricOrdering::Amd,
                CholeskySymbolicParams {
                    supernodal_flop_ratio_threshold: threshold,
                    ..Default::default()
                },
            )?;
            let mut factor = vec![0.0; symbolic.len_val()];
            let req = symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default());
            let mut buf = MemBuffer::new(req);
            symbolic.factorize_numeric_llt::<f64>(
                &mut factor,
                SparseColMatRef::new(sym, &vals),
                Side::Lower,
                Default::default(),
                Par::Seq,
                MemStack::new(&mut buf),
                Default::default(),
            )?;
            let nnz: usize = match symbolic.raw() {
                SymbolicCholeskyRaw::Simplicial(s) => s.len_val(),
                SymbolicCholeskyRaw::Supernodal(s) => s.len_val(),
            };
            // flops of the simplicial count: Σ_j c_j (c_j + 1) / 2 over column counts c_j.
            let flops_ratio = match symbolic.raw() {
                SymbolicCholeskyRaw::Simplicial(s) => {
                    let p = s.col_ptr();
                    let f: f64 = (0..m)
                        .map(|j| {
                            let c = (p[j + 1] - p[j]) as f64;
                            c + c * (c + 1.0) / 2.0
                        })
                        .sum();
                    format!("{:.1}", f / nnz as f64)
                }
                SymbolicCholeskyRaw::Supernodal(_) => "—".into(),
            };
            let solve = median_ms(
                || {
                    let mut x = rhs.clone();
                    let mat = MatMut::from_row_major_slice_mut(x.as_flattened_mut(), m, 3);
                    let req = symbolic.solve_in_place_scratch::<f64>(3, Par::Seq);
                    let mut buf = MemBuffer::new(req);
                    LltRef::new(&symbolic, &factor).solve_in_place_with_conj(
                        Conj::No,
                        mat,
                        Par::Seq,
                        MemStack::new(&mut buf),
                    );
                    std::hint::black_box(x);
                },
                reps,
            );
            let name = std::path::Path::new(path)
                .file_stem()
                .map_or_else(|| path.clone(), |s| s.to_string_lossy().into_owned());
            println!(
                "| {name} | {n} | {picks} | {kind} | {nnz} | {flops_ratio} | {solve:.3} | {ours:.3} |"
            );
        }
    }
    Ok(())
}
