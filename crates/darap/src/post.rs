//! Post-processing of the solved positions (spec §4.3).

use crate::PostProcess;

/// What [`post_process_vjp`] needs.
#[derive(Clone, Debug, PartialEq)]
pub struct PostTape {
    mode: PostProcess,
    /// Recentred positions `q = x − mean(x)`.
    centred: Vec<[f64; 3]>,
    /// `target_diag / diag(q)` (1 unless rescaling).
    scale: f64,
    /// Per axis, the first vertex attaining the max and the min.
    argmax: [usize; 3],
    argmin: [usize; 3],
    /// Per axis, `max − min`, and the bbox diagonal of `q`.
    extent: [f64; 3],
    diag: f64,
    /// Whether the scale depends on the positions (false when the diagonal is 0).
    scale_active: bool,
}

/// Applies the post-processing `mode` to solved positions `x`.
///
/// - [`PostProcess::RecenterRescale`]: `q = x − mean(x)`, then `q · (target_diag / diag(q))`
///   where `diag` is the length of the axis-aligned bounding-box diagonal. If `diag(q)` is 0 the
///   scale is 1.
/// - [`PostProcess::RecenterOnly`]: `x − mean(x)`.
/// - [`PostProcess::None`]: `x` unchanged.
pub fn post_process(
    x: &[[f64; 3]],
    target_diag: f64,
    mode: PostProcess,
) -> (Vec<[f64; 3]>, PostTape) {
    let n = x.len().max(1) as f64;
    let mut mean = [0.0; 3];
    if mode != PostProcess::None {
        for p in x {
            for c in 0..3 {
                mean[c] += p[c];
            }
        }
        mean = mean.map(|m| m / n);
    }
    let centred: Vec<[f64; 3]> = x
        .iter()
        .map(|p| [p[0] - mean[0], p[1] - mean[1], p[2] - mean[2]])
        .collect();
    let mut argmax = [0usize; 3];
    let mut argmin = [0usize; 3];
    // The running extremes in registers (the same comparisons as against `centred[argmax[c]]`).
    if let Some(&first) = centred.first() {
        let (mut hi, mut lo) = (first, first);
        for (i, p) in centred.iter().enumerate() {
            for c in 0..3 {
                if p[c] > hi[c] {
                    hi[c] = p[c];
                    argmax[c] = i;
                }
                if p[c] < lo[c] {
                    lo[c] = p[c];
                    argmin[c] = i;
                }
            }
        }
    }
    let extent: [f64; 3] = if centred.is_empty() {
        [0.0; 3]
    } else {
        std::array::from_fn(|c| centred[argmax[c]][c] - centred[argmin[c]][c])
    };
    let diag = (extent[0] * extent[0] + extent[1] * extent[1] + extent[2] * extent[2]).sqrt();
    let scale_active = mode == PostProcess::RecenterRescale && diag > 0.0 && diag.is_finite();
    let scale = if scale_active {
        target_diag / diag
    } else {
        1.0
    };
    let out = centred.iter().map(|p| p.map(|v| v * scale)).collect();
    (
        out,
        PostTape {
            mode,
            centred,
            scale,
            argmax,
            argmin,
            extent,
            diag,
            scale_active,
        },
    )
}

/// Adjoint of [`post_process`]: gradients flow through the mean and, when rescaling, through the
/// bounding-box extremes (to the first extremal vertex of each axis only).
pub fn post_process_vjp(tape: &PostTape, grad: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let n = grad.len();
    // ∂ℓ/∂q = s·g + (Σ_k g_k·q_k)·∂s/∂q.
    let mut gq: Vec<[f64; 3]> = grad.iter().map(|g| g.map(|v| v * tape.scale)).collect();
    if tape.scale_active {
        let gdotq: f64 = grad
            .iter()
            .zip(&tape.centred)
            .map(|(g, q)| g[0] * q[0] + g[1] * q[1] + g[2] * q[2])
            .sum();
        // s = D0 / D, ∂s/∂D = −s / D, ∂D/∂max_c = extent_c / D = −∂D/∂min_c.
        let ds = -tape.scale / tape.diag * gdotq;
        for c in 0..3 {
            let w = ds * tape.extent[c] / tape.diag;
            gq[tape.argmax[c]][c] += w;
            gq[tape.argmin[c]][c] -= w;
        }
    }
    if tape.mode == PostProcess::None || n == 0 {
        return gq;
    }
    let mut mean = [0.0; 3];
    for g in &gq {
        for c in 0..3 {
            mean[c] += g[c];
        }
    }
    let mean = mean.map(|m| m / n as f64);
    for g in &mut gq {
        *g = [g[0] - mean[0], g[1] - mean[1], g[2] - mean[2]];
    }
    gq
}
