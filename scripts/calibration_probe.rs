//! Calibration probe for benchmark sessions on a shared VM (docs/benchmarks.md, issue 10,
//! target 3, thirteenth pass). Single thread; prints the best of five of each part in ms:
//! - `sqrt`: a 20M-step dependent `sqrt` chain (the core's clock);
//! - `walk`: a 2M-step walk along one random cycle through 64 MiB (memory latency; on
//!   2026-12-02 it followed the VM's slow phase for an hour, then not);
//! - `fma`: 32 independent `f64` FMA chains, 200M FMAs, reported as cycles per FMA at the clock
//!   that a dependent FMA chain gives (0.125 = both FMA pipes busy; more means the core is shared).
//!
//! Not part of the workspace: `rustc -O -C target-cpu=native scripts/calibration_probe.rs -o
//! /tmp/calibration_probe && taskset -c 1 /tmp/calibration_probe`.

use std::hint::black_box;
use std::time::Instant;

fn best_of_5(mut f: impl FnMut() -> f64) -> f64 {
    (0..5).map(|_| f()).fold(f64::INFINITY, f64::min)
}

fn main() {
    let n = 64 * 1024 * 1024 / 8;
    // Sattolo's shuffle with an LCG: one cycle through every slot.
    let mut next: Vec<usize> = (0..n).collect();
    let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
    for i in (1..n).rev() {
        s = s
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        next.swap(i, (s >> 33) as usize % i);
    }
    let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
    let sqrt = best_of_5(|| {
        let t = Instant::now();
        let mut x = black_box(2.0f64);
        for _ in 0..20_000_000 {
            x = (x + 1.0).sqrt();
        }
        black_box(x);
        ms(t)
    });
    let walk = best_of_5(|| {
        let t = Instant::now();
        let mut p = 0usize;
        for _ in 0..2_000_000 {
            p = next[p];
        }
        black_box(p);
        ms(t)
    });
    const FMAS: usize = 200_000_000;
    const CHAINS: usize = 32;
    let (m, c) = (black_box(0.999_999f64), black_box(1e-9f64));
    let dependent = best_of_5(|| {
        let t = Instant::now();
        let mut x = black_box(1.0f64);
        for _ in 0..FMAS {
            x = x.mul_add(m, c);
        }
        black_box(x);
        ms(t)
    });
    let independent = best_of_5(|| {
        let t = Instant::now();
        let mut a = [black_box(1.0f64); CHAINS];
        for _ in 0..FMAS / CHAINS {
            for x in &mut a {
                *x = x.mul_add(m, c);
            }
        }
        black_box(a);
        ms(t)
    });
    // A dependent FMA takes 4 cycles on the machines measured (AMD Zen 3).
    let ghz = 4.0 * FMAS as f64 / (dependent * 1e6);
    let cycles_per_fma = independent * 1e6 * ghz / FMAS as f64;
    println!(
        "sqrt {sqrt:.1} ms  walk {walk:.1} ms  fma {cycles_per_fma:.3} cycles/FMA at {ghz:.2} GHz"
    );
}
