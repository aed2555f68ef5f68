//! Silhouette antialiasing with a visibility gradient, after nvdiffrast's `antialias`
//! (Laine et al. 2020, "Modular Primitives for High-Performance Differentiable Rendering", §3.4).
//!
//! Forward. For every pair of horizontally or vertically adjacent pixels A, B whose triangle ids
//! differ, the *front* pixel F is the covered one (if the other is background) or the nearer one.
//! Let T be F's triangle. If the segment between the two pixel centres leaves T through one of T's
//! **silhouette edges** — a boundary edge, a non-manifold edge, or an edge whose two faces face
//! opposite ways as seen from the eye — let t ∈ [0, 1] be where the edge crosses the segment,
//! measured from F's centre towards the other pixel O's centre. Then
//! - t > 1/2 (the edge lies in O's half): O is partly covered by T:
//!   c_O += (t − 1/2)·(c_F − c_O);
//! - t < 1/2 (the edge lies in F's half): F is partly uncovered:
//!   c_F += (1/2 − t)·(c_O − c_F).
//!
//! All colours on the right are the pre-antialiasing colours, so the deltas of all pairs add up in
//! any order. The result is continuous in the edge position while the edge stays between the two
//! pixel centres, which is what gives silhouettes a gradient.
//!
//! Adjoint. The blend is linear in the colours for a fixed weight α, and α = ±(t − 1/2) is a smooth
//! function of the edge's screen end points; t follows the screen end points through the line
//! crossing, and those follow the two edge vertices through the perspective projection.

use std::borrow::Cow;

use glam::DVec3;

use super::raster::{Camera, NO_TRIANGLE, Projected};

/// Neighbour of a face across its edge k (corners k → k+1): a face index, or one of these markers.
pub const BOUNDARY_EDGE: u32 = u32::MAX;
/// Marker for an edge shared by more than two faces.
pub const NON_MANIFOLD_EDGE: u32 = u32::MAX - 1;

/// Face adjacency across each edge: `adj[f][k]` is the face across the edge `(f[k], f[k+1])`.
pub fn face_adjacency(faces: &[[u32; 3]]) -> Vec<[u32; 3]> {
    let mut keyed: Vec<(u32, u32, u32, u8)> = Vec::with_capacity(faces.len() * 3);
    for (fi, f) in faces.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            keyed.push((a.min(b), a.max(b), fi as u32, k as u8));
        }
    }
    keyed.sort_unstable();
    let mut adj = vec![[BOUNDARY_EDGE; 3]; faces.len()];
    let mut i = 0;
    while i < keyed.len() {
        let mut j = i + 1;
        while j < keyed.len() && keyed[j].0 == keyed[i].0 && keyed[j].1 == keyed[i].1 {
            j += 1;
        }
        let group = &keyed[i..j];
        if group.len() == 2 {
            adj[group[0].2 as usize][group[0].3 as usize] = group[1].2;
            adj[group[1].2 as usize][group[1].3 as usize] = group[0].2;
        } else if group.len() > 2 {
            for e in group {
                adj[e.2 as usize][e.3 as usize] = NON_MANIFOLD_EDGE;
            }
        }
        i = j;
    }
    adj
}

/// One antialiasing blend: `c[target] += alpha · (c[source] − c[target])`.
#[derive(Clone, Copy, Debug)]
pub struct Blend {
    /// Pixel whose colour changes (index within the view).
    pub target: u32,
    /// Pixel whose colour is blended in.
    pub source: u32,
    /// The silhouette edge's vertices.
    pub edge: [u32; 2],
    /// Blend weight in [0, 1/2].
    pub alpha: f64,
    /// dα/dx of the two edge vertices (world space).
    pub d_alpha: [DVec3; 2],
}

/// Is face `f` front-facing from `eye` (its normal g_f points towards the eye)?
#[inline(always)]
fn front_facing(g: DVec3, x0: DVec3, eye: DVec3) -> bool {
    g.dot(eye - x0) > 0.0
}

/// The silhouette-edge mask of triangle `t` (0 for the background). A function, not a closure:
/// it is called inside the dispatched kernel.
#[inline(always)]
fn silhouette_mask(silhouettes: &[u8], t: u32) -> u8 {
    if t == NO_TRIANGLE {
        0
    } else {
        silhouettes[t as usize]
    }
}

/// Finds the blends of one view. `ids` and `depth` come from the rasterizer, `face_raw` are the
/// unnormalized face normals, `proj` the projected vertices. Runs under the run-time SIMD
/// dispatch (the same results on every instruction set).
#[allow(clippy::too_many_arguments)]
pub fn find_blends(
    vertices: &[[f64; 3]],
    faces: &[[u32; 3]],
    adjacency: &[[u32; 3]],
    face_raw: &[DVec3],
    camera: &Camera,
    proj: &[Projected],
    ids: &[u32],
    depth: &[f64],
) -> Vec<Blend> {
    super::simd::dispatch(FindBlends {
        vertices,
        faces,
        adjacency,
        face_raw,
        camera,
        proj,
        ids,
        depth,
    })
}

/// [`find_blends`]'s arguments, as a dispatch kernel.
pub(super) struct FindBlends<'a> {
    pub(super) vertices: &'a [[f64; 3]],
    pub(super) faces: &'a [[u32; 3]],
    pub(super) adjacency: &'a [[u32; 3]],
    pub(super) face_raw: &'a [DVec3],
    pub(super) camera: &'a Camera,
    pub(super) proj: &'a [Projected],
    pub(super) ids: &'a [u32],
    pub(super) depth: &'a [f64],
}

impl pulp::WithSimd for FindBlends<'_> {
    type Output = Vec<Blend>;
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> Vec<Blend> {
        let Self {
            vertices,
            faces,
            adjacency,
            face_raw,
            camera,
            proj,
            ids,
            depth,
        } = self;
        // Per face, which of its edges are silhouettes from this eye (bit k: edge f[k] → f[k+1]),
        // decided once per view: most pixel pairs with different ids lie inside the surface, on
        // triangles without a silhouette edge, and are skipped on one load.
        let facing: Vec<bool> = faces
            .iter()
            .zip(face_raw)
            .map(|(f, &g)| front_facing(g, DVec3::from(vertices[f[0] as usize]), camera.eye))
            .collect();
        let silhouettes: Vec<u8> = adjacency
            .iter()
            .zip(&facing)
            .map(|(adj, &front)| {
                (0..3).fold(0u8, |mask, k| {
                    let silhouette = match adj[k] {
                        BOUNDARY_EDGE | NON_MANIFOLD_EDGE => true,
                        other => front != facing[other as usize],
                    };
                    mask | (u8::from(silhouette) << k)
                })
            })
            .collect();
        let (w, h) = (camera.width, camera.height);
        let mut blends = Vec::new();
        // Candidate pairs (pixel a, axis): axis 0 pairs a with its right neighbour, axis 1 with the
        // pixel below. Gathered in a tight scan first; almost all pairs have equal ids, and of
        // those that differ, most lie between triangles without a silhouette edge: the triangle
        // the pair is tested against (the front one, below) is one of the two, so a pair where
        // neither has one is dropped here, without the depth test.
        let mut pairs = Vec::new();
        for row in 0..h {
            let r = &ids[row * w..(row + 1) * w];
            for col in 0..w.saturating_sub(1) {
                if r[col] != r[col + 1]
                    && silhouette_mask(&silhouettes, r[col])
                        | silhouette_mask(&silhouettes, r[col + 1])
                        != 0
                {
                    pairs.push((row * w + col, 0usize));
                }
            }
            if row + 1 < h {
                let below = &ids[(row + 1) * w..(row + 2) * w];
                for col in 0..w {
                    if r[col] != below[col]
                        && silhouette_mask(&silhouettes, r[col])
                            | silhouette_mask(&silhouettes, below[col])
                            != 0
                    {
                        pairs.push((row * w + col, 1usize));
                    }
                }
            }
        }
        for (a, axis) in pairs {
            let b = if axis == 0 { a + 1 } else { a + w };
            let (ia, ib) = (ids[a], ids[b]);
            let a_front = ib == NO_TRIANGLE || (ia != NO_TRIANGLE && depth[a] <= depth[b]);
            let (front, other) = if a_front { (a, b) } else { (b, a) };
            let tri = ids[front];
            let mask = silhouettes[tri as usize];
            if mask == 0 {
                continue;
            }
            let centre = |p: usize| [(p % w) as f64 + 0.5, (p / w) as f64 + 0.5];
            let (cf, co) = (centre(front), centre(other));
            let face = faces[tri as usize];
            for k in 0..3 {
                if mask & (1 << k) == 0 {
                    continue;
                }
                let (va, vb) = (face[k], face[(k + 1) % 3]);
                if proj[va as usize].cam.z <= 0.0 || proj[vb as usize].cam.z <= 0.0 {
                    continue; // only reachable with externally supplied visibility
                }
                let (sa, sb) = (proj[va as usize].screen, proj[vb as usize].screen);
                // The segment runs along `axis`; the crossing line is coordinate `o` = const.
                let o = 1 - axis;
                let line = cf[o];
                let (da, db) = (sa[o] - line, sb[o] - line);
                if da * db >= 0.0 {
                    continue;
                }
                let den = sb[o] - sa[o];
                let s = (line - sa[o]) / den;
                let cross = sa[axis] + s * (sb[axis] - sa[axis]);
                let step = co[axis] - cf[axis]; // ±1
                let t = (cross - cf[axis]) / step;
                if !(0.0..=1.0).contains(&t) {
                    continue;
                }
                // d cross / d(screen of a, b) along `axis` and `o`.
                let slope = (sb[axis] - sa[axis]) / den;
                let mut ds_a = [0.0; 2];
                let mut ds_b = [0.0; 2];
                ds_a[axis] = 1.0 - s;
                ds_b[axis] = s;
                ds_a[o] = slope * (s - 1.0);
                ds_b[o] = -slope * s;
                let (target, source, alpha, dalpha_dt) = if t > 0.5 {
                    (other, front, t - 0.5, 1.0)
                } else {
                    (front, other, 0.5 - t, -1.0)
                };
                let scale = dalpha_dt / step;
                let ja = camera.screen_jacobian(proj[va as usize].cam);
                let jb = camera.screen_jacobian(proj[vb as usize].cam);
                let d_alpha = [
                    (ja[0] * ds_a[0] + ja[1] * ds_a[1]) * scale,
                    (jb[0] * ds_b[0] + jb[1] * ds_b[1]) * scale,
                ];
                blends.push(Blend {
                    target: target as u32,
                    source: source as u32,
                    edge: [va, vb],
                    alpha,
                    d_alpha,
                });
                break;
            }
        }
        blends
    }
}

/// Applies the blends to one view's colours: returns the antialiased colours.
pub fn apply(colour: &[f64], blends: &[Blend]) -> Vec<f64> {
    let mut out = colour.to_vec();
    for (t, value) in blended_pixels(colour, blends) {
        out[t as usize] = value;
    }
    out
}

/// The pixels the blends change, each once and in increasing order, with their antialiased
/// colour: `colour[t]` plus each of its blends' `α·(colour[s] − colour[t])`, added in the blends'
/// order (the values [`apply`] gives them). Every other pixel keeps its colour, so a caller that
/// already holds the colours writes these few values instead of copying the whole view.
pub fn blended_pixels(colour: &[f64], blends: &[Blend]) -> Vec<(u32, f64)> {
    let mut order: Vec<u32> = (0..blends.len() as u32).collect();
    // Stable: a pixel's blends stay in their order.
    order.sort_by_key(|&k| blends[k as usize].target);
    let mut out: Vec<(u32, f64)> = Vec::with_capacity(order.len());
    for k in order {
        let b = &blends[k as usize];
        let (t, s) = (b.target as usize, b.source as usize);
        let delta = b.alpha * (colour[s] - colour[t]);
        match out.last_mut() {
            Some((last, value)) if *last == b.target => *value += delta,
            _ => out.push((b.target, colour[t] + delta)),
        }
    }
    out
}

/// Adjoint of [`apply`]: from dL/d(out) returns dL/d(colour) and adds the visibility gradient
/// dL/dα · dα/dx to the vertices' dL/dx through `add_d_vertex(vertex, value)`, blend after blend
/// (the caller's accumulator, whatever its layout). Works in `d_out`'s buffer when it owns one (no
/// copy).
pub fn apply_adjoint<'a>(
    colour: &[f64],
    blends: &[Blend],
    d_out: Cow<'a, [f64]>,
    mut add_d_vertex: impl FnMut(usize, DVec3),
) -> Cow<'a, [f64]> {
    if blends.is_empty() {
        return d_out;
    }
    // Every blend reads dL/d(out) at its target before any blend writes: gather those first,
    // then update in place.
    let g_target: Vec<f64> = blends.iter().map(|b| d_out[b.target as usize]).collect();
    let mut d_colour = d_out.into_owned();
    for (b, &g) in blends.iter().zip(&g_target) {
        let (t, s) = (b.target as usize, b.source as usize);
        d_colour[s] += g * b.alpha;
        d_colour[t] -= g * b.alpha;
        let d_alpha = g * (colour[s] - colour[t]);
        add_d_vertex(b.edge[0] as usize, b.d_alpha[0] * d_alpha);
        add_d_vertex(b.edge[1] as usize, b.d_alpha[1] * d_alpha);
    }
    d_colour.into()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Blends with repeated targets, pixels that are both a target and a source, in no order.
    fn tangled_blends(pixels: u32) -> Vec<Blend> {
        (0..3 * pixels)
            .map(|k| {
                let target = (k * 7 + 3) % pixels;
                Blend {
                    target,
                    source: (target + 1 + k % 5) % pixels,
                    edge: [k % pixels, (k * 3 + 1) % pixels],
                    alpha: 0.5 * f64::from((k * 37) % 101) / 101.0,
                    d_alpha: [
                        DVec3::new(f64::from(k) * 0.1, -0.3, 0.7),
                        DVec3::new(0.2, f64::from(k % 9) - 4.0, 1.3),
                    ],
                }
            })
            .collect()
    }

    fn colours(pixels: u32) -> Vec<f64> {
        (0..pixels)
            .map(|i| (f64::from(i) * 0.618).fract() * 0.8)
            .collect()
    }

    #[test]
    fn blended_pixels_are_the_plain_blend_loop_bit_for_bit() {
        let pixels = 23;
        let colour = colours(pixels);
        let blends = tangled_blends(pixels);
        // The definition: every blend adds to its target, reading the unblended colours.
        let mut want = colour.clone();
        for b in &blends {
            let (t, s) = (b.target as usize, b.source as usize);
            want[t] += b.alpha * (colour[s] - colour[t]);
        }
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&apply(&colour, &blends)), bits(&want));
        let changed = blended_pixels(&colour, &blends);
        assert!(changed.windows(2).all(|w| w[0].0 < w[1].0));
        let mut targets: Vec<u32> = blends.iter().map(|b| b.target).collect();
        targets.sort_unstable();
        targets.dedup();
        assert_eq!(changed.iter().map(|c| c.0).collect::<Vec<_>>(), targets);
    }

    #[test]
    fn in_place_adjoint_is_the_copying_one_bit_for_bit() {
        let pixels = 23;
        let colour = colours(pixels);
        let blends = tangled_blends(pixels);
        let d_out: Vec<f64> = (0..pixels).map(|i| f64::from(i % 7) - 2.5).collect();
        // The definition, reading dL/d(out) from a buffer no blend writes.
        let mut want = d_out.clone();
        let mut want_dx = vec![DVec3::ZERO; pixels as usize];
        for b in &blends {
            let (t, s) = (b.target as usize, b.source as usize);
            let g = d_out[t];
            want[s] += g * b.alpha;
            want[t] -= g * b.alpha;
            let d_alpha = g * (colour[s] - colour[t]);
            want_dx[b.edge[0] as usize] += b.d_alpha[0] * d_alpha;
            want_dx[b.edge[1] as usize] += b.d_alpha[1] * d_alpha;
        }
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let dbits = |v: &[DVec3]| {
            v.iter()
                .map(|x| x.to_array().map(f64::to_bits))
                .collect::<Vec<_>>()
        };
        for owned in [false, true] {
            let mut dx = vec![DVec3::ZERO; pixels as usize];
            let input = if owned {
                Cow::Owned(d_out.clone())
            } else {
                Cow::Borrowed(&d_out[..])
            };
            let got = apply_adjoint(&colour, &blends, input, |v, g| dx[v] += g);
            assert_eq!(bits(&got), bits(&want));
            assert_eq!(dbits(&dx), dbits(&want_dx));
        }
    }
}
