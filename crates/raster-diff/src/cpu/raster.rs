//! Camera frames, perspective projection and rasterization with a depth test.
//!
//! Camera frame (right-handed world, +y up): forward f = normalize(target − eye),
//! right r = normalize(f × up), camera up u = r × f. Camera coordinates of a point X are
//! (r·(X − eye), u·(X − eye), f·(X − eye)); the third is the depth z (positive in front).
//!
//! Screen coordinates are in pixels with the origin at the top-left image corner, x to the right,
//! y down: sx = W/2 + k·x_c/z, sy = H/2 − k·y_c/z with k = (H/2)/tan(fov_y/2) (square pixels).
//! Pixel (column i, row j) has its centre at (i + 0.5, j + 0.5) and is covered by a triangle when
//! its centre is inside. Centres exactly on an edge follow the top-left rule (in the y-down frame,
//! after orienting the triangle clockwise on screen: an edge is owned when it goes up, dy < 0, or is
//! horizontal going right, dy = 0 and dx > 0), so a centre on an edge shared by two triangles is
//! covered exactly once. The edge function E(a, b, p) = (a − p) × (b − p) is evaluated in a form
//! that is exactly antisymmetric in (a, b), so shared edges are watertight in floating point.
//!
//! Clipping: a triangle with any vertex nearer than the near plane (depth 0.5 by default) is not
//! drawn (no partial clipping); the far plane is at infinity. No back-face culling: back faces are
//! only skipped where nearer surfaces already hide them (an exact shortcut: the band kernel of
//! [`rasterize`] draws front faces first; see `docs/renderer.md`).
//! Depth test: nearest depth wins; equal depths go to the smaller triangle index (deterministic).

use glam::DVec3;
use rayon::prelude::*;

use crate::{RenderError, View};

/// Triangle id of a pixel that no triangle covers.
pub const NO_TRIANGLE: u32 = u32::MAX;

/// Rows per rasterization band (the unit of parallel work within a view).
const BAND_ROWS: usize = 32;

/// One view's camera frame, projection and light.
#[derive(Clone, Debug)]
pub struct Camera {
    pub eye: DVec3,
    pub right: DVec3,
    pub up: DVec3,
    pub forward: DVec3,
    pub light: DVec3,
    /// Pixels per unit of x_c/z (and y_c/z).
    pub k: f64,
    pub cx: f64,
    pub cy: f64,
    pub width: usize,
    pub height: usize,
}

impl Camera {
    /// Builds the frame of `view` for a `width`×`height` image.
    pub fn new(view: &View, width: usize, height: usize) -> Result<Self, RenderError> {
        let eye = DVec3::from(view.eye);
        let target = DVec3::from(view.target);
        let light = DVec3::from(view.light_pos);
        let world_up = DVec3::from(view.up);
        if !(eye.is_finite() && target.is_finite() && light.is_finite() && world_up.is_finite()) {
            return Err(RenderError::InvalidInput(
                "view has a non-finite eye, target, up or light".into(),
            ));
        }
        if !(view.fov_y_deg > 0.0 && view.fov_y_deg < 180.0) {
            return Err(RenderError::InvalidInput(format!(
                "field of view {}° is not in (0°, 180°)",
                view.fov_y_deg
            )));
        }
        let forward = (target - eye)
            .try_normalize()
            .ok_or_else(|| RenderError::InvalidInput("view eye equals its target".into()))?;
        let right = forward.cross(world_up).try_normalize().ok_or_else(|| {
            RenderError::InvalidInput("view up is parallel to the viewing direction".into())
        })?;
        let up = right.cross(forward);
        let k = 0.5 * height as f64 / (0.5 * view.fov_y_deg.to_radians()).tan();
        Ok(Self {
            eye,
            right,
            up,
            forward,
            light,
            k,
            cx: 0.5 * width as f64,
            cy: 0.5 * height as f64,
            width,
            height,
        })
    }

    /// Camera coordinates (x_c, y_c, z) of a world point.
    #[inline]
    pub fn to_camera(&self, x: DVec3) -> DVec3 {
        let p = x - self.eye;
        DVec3::new(p.dot(self.right), p.dot(self.up), p.dot(self.forward))
    }

    /// Screen position (sx, sy) in pixels of camera coordinates `c` (z > 0).
    #[inline]
    pub fn project(&self, c: DVec3) -> [f64; 2] {
        [self.cx + self.k * c.x / c.z, self.cy - self.k * c.y / c.z]
    }

    /// Gradients of (sx, sy) with respect to the world point whose camera coordinates are `c`.
    #[inline(always)]
    pub fn screen_jacobian(&self, c: DVec3) -> [DVec3; 2] {
        let iz = 1.0 / c.z;
        [
            (self.right - self.forward * (c.x * iz)) * (self.k * iz),
            -(self.up - self.forward * (c.y * iz)) * (self.k * iz),
        ]
    }

    /// World direction of the ray through screen point (sx, sy) (unit depth along `forward`).
    #[inline(always)]
    pub fn pixel_ray(&self, sx: f64, sy: f64) -> DVec3 {
        self.right * ((sx - self.cx) / self.k) - self.up * ((sy - self.cy) / self.k) + self.forward
    }
}

/// Projected vertex: camera coordinates and screen position.
#[derive(Clone, Copy, Debug)]
pub struct Projected {
    pub cam: DVec3,
    pub screen: [f64; 2],
}

/// Projects every vertex (screen positions are meaningless for z ≤ 0; such faces are not drawn).
pub fn project_vertices(camera: &Camera, vertices: &[[f64; 3]]) -> Vec<Projected> {
    vertices
        .iter()
        .map(|x| {
            let cam = camera.to_camera(DVec3::from(*x));
            Projected {
                cam,
                screen: camera.project(cam),
            }
        })
        .collect()
}

/// Exactly antisymmetric edge function E(a, b, p) = (a − p) × (b − p): twice the signed area of
/// (p, a, b); positive when p lies to the interior side of a clockwise-on-screen edge a → b.
#[inline(always)]
fn edge(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> f64 {
    (a[0] - p[0]) * (b[1] - p[1]) - (a[1] - p[1]) * (b[0] - p[0])
}

/// Top-left ownership of edge a → b (triangle oriented clockwise on screen, y down).
#[inline(always)]
fn owns(a: [f64; 2], b: [f64; 2]) -> bool {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    dy < 0.0 || (dy == 0.0 && dx > 0.0)
}

/// Triangle set up for scan conversion.
struct Setup {
    s: [[f64; 2]; 3],
    inv_z: [f64; 3],
    inv_area2: f64,
    owned: [bool; 3],
    cols: (usize, usize),
    rows: (usize, usize),
    /// The nearest corner's depth, or 0 for a sliver (never skipped; see [`OCCLUSION_MARGIN`]).
    z_near: f64,
    /// Whether the corners were counter-clockwise on screen (y down) as given, i.e. the face
    /// is seen from its front for a mesh whose faces are counter-clockwise seen from outside.
    front: bool,
}

#[inline(always)]
fn setup(
    face: &[u32; 3],
    proj: &[Projected],
    near: f64,
    width: usize,
    height: usize,
) -> Option<Setup> {
    let mut c = [
        proj[face[0] as usize],
        proj[face[1] as usize],
        proj[face[2] as usize],
    ];
    if c.iter().any(|p| p.cam.z < near || p.cam.z.is_nan()) {
        return None;
    }
    let mut area2 = edge(c[0].screen, c[1].screen, c[2].screen);
    if area2 == 0.0 || !area2.is_finite() {
        return None;
    }
    let front = area2 < 0.0;
    if area2 < 0.0 {
        c.swap(1, 2);
        area2 = -area2;
    }
    let s = [c[0].screen, c[1].screen, c[2].screen];
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for p in &s {
        x0 = x0.min(p[0]);
        x1 = x1.max(p[0]);
        y0 = y0.min(p[1]);
        y1 = y1.max(p[1]);
    }
    // Pixel centres i + 0.5 inside [x0, x1].
    let (c0, c1) = (
        (x0 - 0.5).ceil().max(0.0),
        (x1 - 0.5).floor().min(width as f64 - 1.0),
    );
    let (r0, r1) = (
        (y0 - 0.5).ceil().max(0.0),
        (y1 - 0.5).floor().min(height as f64 - 1.0),
    );
    if c0 > c1 || r0 > r1 {
        return None;
    }
    Some(Setup {
        s,
        inv_z: [1.0 / c[0].cam.z, 1.0 / c[1].cam.z, 1.0 / c[2].cam.z],
        inv_area2: 1.0 / area2,
        // Edge opposite corner i is (i+1 → i+2).
        owned: [owns(s[1], s[2]), owns(s[2], s[0]), owns(s[0], s[1])],
        cols: (c0 as usize, c1 as usize),
        rows: (r0 as usize, r1 as usize),
        z_near: {
            let d = (x1 - x0).max(y1 - y0) + 1.0;
            if d * d <= SLIVER_RATIO * area2 {
                c[0].cam.z.min(c[1].cam.z).min(c[2].cam.z)
            } else {
                0.0
            }
        },
        front,
    })
}

/// [`setup`] of every face, as a [`crate::cpu::simd::dispatch`] kernel (the pixel-range
/// roundings become single instructions where SSE4.1 is present, instead of calls).
struct SetupAll<'a> {
    faces: &'a [[u32; 3]],
    proj: &'a [Projected],
    near: f64,
    width: usize,
    height: usize,
}

impl pulp::WithSimd for SetupAll<'_> {
    type Output = Vec<Option<Setup>>;
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> Vec<Option<Setup>> {
        let mut setups = Vec::with_capacity(self.faces.len());
        for f in self.faces {
            setups.push(setup(f, self.proj, self.near, self.width, self.height));
        }
        setups
    }
}

/// Columns whose edge functions are evaluated together (one 256-bit register of f64).
const LANES: usize = 4;

/// Side in pixels of the square depth tiles of [`RasterBand`]'s occlusion test.
const TILE: usize = 8;

/// Relative margin of the occlusion test: a triangle is skipped only when its nearest corner is
/// farther than `1 + OCCLUSION_MARGIN` times the farthest depth already in its tiles.
///
/// Why that is safe: a covered pixel has e_i ≥ 0 and depth z = 1 / ((Σ e_i/z_i) / A) with A the
/// doubled area; in exact arithmetic Σ e_i = A, so z ≥ min_i z_i. In floating point each edge
/// function E = (a − p) × (b − p) is off by at most 2⁻⁵³|E| + 18·2⁻⁵³·D² with D the bounding box's
/// larger side plus one (the differences are exactly rounded, each product has |·| ≤ (1.5 D)²),
/// and so is A: together Σ e_i / A ≤ 1 + 2⁻⁵² + 108·2⁻⁵³·D²/A, plus a few ulps for the last
/// operations — below 1 + 10⁻⁹ when D² ≤ [`SLIVER_RATIO`]·A (108·2⁻⁵³·2¹⁴ ≈ 2·10⁻¹⁰). Slivers
/// beyond that ratio are never skipped. So a skipped triangle could not have passed the depth
/// test at any pixel.
const OCCLUSION_MARGIN: f64 = 2e-9;

/// Triangles with (bounding box side + 1)² > `SLIVER_RATIO` × doubled area are slivers, which the
/// occlusion test leaves alone (see [`OCCLUSION_MARGIN`]).
const SLIVER_RATIO: f64 = 16384.0;

/// One band of rows of [`rasterize`], as a [`crate::cpu::simd::dispatch`] kernel: the triangles
/// binned to it, each scan-converted over its bounding box within the band.
/// The edge functions of [`LANES`] neighbouring pixel centres are evaluated together (the same
/// expression per lane, so the same values as one at a time); the coverage rule and the depth
/// test then run per covered pixel.
///
/// Front faces ([`Setup::front`]) go first; then each back face is skipped when its nearest corner
/// lies beyond the farthest depth already stored in the [`TILE`]-pixel tiles its box touches
/// (see [`OCCLUSION_MARGIN`]) — on a closed mesh seen from outside, nearly all of them. The result
/// does not depend on the order: per pixel it is the smallest (depth, triangle index) pair, which
/// the depth test with its index tie-break computes in any order; and a skipped triangle would not
/// have changed it. Tested against the plain single pass over all triangles in index order.
struct RasterBand<'a> {
    setups: &'a [Option<Setup>],
    bin: &'a [u32],
    row_base: usize,
    width: usize,
    height: usize,
    ids: &'a mut [u32],
    depth: &'a mut [f64],
}

impl pulp::WithSimd for RasterBand<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let Self {
            setups,
            bin,
            row_base,
            width,
            height,
            ids,
            depth,
        } = self;
        let row_end = (row_base + BAND_ROWS).min(height);
        for &t in bin {
            if let Some(s) = &setups[t as usize]
                && s.front
            {
                scan(s, t, row_base, row_end, width, ids, depth);
            }
        }
        // The farthest depth per tile of the band after the front faces (+∞ where any pixel is
        // still background), tiles of TILE × TILE pixels, row-major.
        let tiles_x = width.div_ceil(TILE);
        let mut tile_far = vec![0.0f64; tiles_x * BAND_ROWS.div_ceil(TILE)];
        for (r, line) in depth.chunks_exact(width).enumerate() {
            let far_row = &mut tile_far[(r / TILE) * tiles_x..][..tiles_x];
            for (far, d) in far_row.iter_mut().zip(line.chunks(TILE)) {
                // A NaN depth (none is expected) counts as +∞: it never lets a triangle be skipped.
                *far = d.iter().fold(*far, |m, &z| {
                    if z.is_nan() {
                        f64::INFINITY
                    } else if z > m {
                        z
                    } else {
                        m
                    }
                });
            }
        }
        for &t in bin {
            let Some(s) = &setups[t as usize] else {
                continue;
            };
            if s.front {
                continue;
            }
            let (lo, hi) = (s.rows.0.max(row_base), s.rows.1.min(row_end - 1));
            if lo > hi {
                continue;
            }
            let mut far = 0.0f64;
            for tr in (lo - row_base) / TILE..=(hi - row_base) / TILE {
                for &z in &tile_far[tr * tiles_x + s.cols.0 / TILE..=tr * tiles_x + s.cols.1 / TILE]
                {
                    if z > far {
                        far = z;
                    }
                }
            }
            if s.z_near > far * (1.0 + OCCLUSION_MARGIN) {
                continue;
            }
            scan(s, t, row_base, row_end, width, ids, depth);
        }
    }
}

/// Scan-converts triangle `t` over its bounding box within the band's rows
/// `row_base..row_end` (see [`RasterBand`]).
#[inline(always)]
fn scan(
    s: &Setup,
    t: u32,
    row_base: usize,
    row_end: usize,
    width: usize,
    ids: &mut [u32],
    depth: &mut [f64],
) {
    for row in s.rows.0.max(row_base)..=s.rows.1.min(row_end - 1) {
        let py = row as f64 + 0.5;
        let line = (row - row_base) * width;
        let mut col = s.cols.0;
        while col <= s.cols.1 {
            let n = (s.cols.1 + 1 - col).min(LANES);
            let mut px = [0.0; LANES];
            for (l, x) in px.iter_mut().enumerate() {
                *x = (col + l) as f64 + 0.5;
            }
            let e = [
                edge_lanes(s.s[1], s.s[2], px, py),
                edge_lanes(s.s[2], s.s[0], px, py),
                edge_lanes(s.s[0], s.s[1], px, py),
            ];
            for l in 0..n {
                let (e0, e1, e2) = (e[0][l], e[1][l], e[2][l]);
                let inside = (e0 > 0.0 || (e0 == 0.0 && s.owned[0]))
                    && (e1 > 0.0 || (e1 == 0.0 && s.owned[1]))
                    && (e2 > 0.0 || (e2 == 0.0 && s.owned[2]));
                if !inside {
                    continue;
                }
                let inv_z = (e0 * s.inv_z[0] + e1 * s.inv_z[1] + e2 * s.inv_z[2]) * s.inv_area2;
                let z = 1.0 / inv_z;
                let i = line + col + l;
                if z < depth[i] || (z == depth[i] && t < ids[i]) {
                    depth[i] = z;
                    ids[i] = t;
                }
            }
            col += LANES;
        }
    }
}

/// [`edge`] at the pixel centres `(px[l], py)`, lane by lane (the same operations).
#[inline(always)]
fn edge_lanes(a: [f64; 2], b: [f64; 2], px: [f64; LANES], py: f64) -> [f64; LANES] {
    let mut e = [0.0; LANES];
    for l in 0..LANES {
        e[l] = edge(a, b, [px[l], py]);
    }
    e
}

/// Rasterizes one view: per pixel (row-major, row 0 at the top) the visible triangle id
/// ([`NO_TRIANGLE`] for background) and its depth (+∞ for background).
pub fn rasterize(
    faces: &[[u32; 3]],
    proj: &[Projected],
    near: f64,
    width: usize,
    height: usize,
) -> (Vec<u32>, Vec<f64>) {
    let setups = crate::cpu::simd::dispatch(SetupAll {
        faces,
        proj,
        near,
        width,
        height,
    });
    let bands = height.div_ceil(BAND_ROWS);
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (t, s) in setups.iter().enumerate() {
        if let Some(s) = s {
            for b in s.rows.0 / BAND_ROWS..=s.rows.1 / BAND_ROWS {
                bins[b].push(t as u32);
            }
        }
    }
    let mut ids = vec![NO_TRIANGLE; width * height];
    let mut depth = vec![f64::INFINITY; width * height];
    ids.par_chunks_mut(BAND_ROWS * width)
        .zip(depth.par_chunks_mut(BAND_ROWS * width))
        .zip(bins.par_iter())
        .enumerate()
        .for_each(|(band, ((ids, depth), bin))| {
            crate::cpu::simd::dispatch(RasterBand {
                setups: &setups,
                bin,
                row_base: band * BAND_ROWS,
                width,
                height,
                ids,
                depth,
            })
        });
    (ids, depth)
}

#[cfg(test)]
mod tests {
    use super::*;
    use pulp::WithSimd;

    /// The plain z-buffer: every triangle in index order over its whole bounding box, no
    /// orientation passes, no occlusion test.
    fn rasterize_single_pass(
        faces: &[[u32; 3]],
        proj: &[Projected],
        (width, height): (usize, usize),
    ) -> (Vec<u32>, Vec<f64>) {
        let mut ids = vec![NO_TRIANGLE; width * height];
        let mut depth = vec![f64::INFINITY; width * height];
        for (t, f) in faces.iter().enumerate() {
            if let Some(s) = setup(f, proj, 0.5, width, height) {
                scan(&s, t as u32, 0, height, width, &mut ids, &mut depth);
            }
        }
        (ids, depth)
    }

    /// Same ids and depth bits as the single pass, on a closed mesh (most back faces skipped),
    /// the same mesh turned inside out (its "front" faces are the hidden ones), an open mesh
    /// (back faces visible through the hole), coincident faces of both orientations (equal
    /// depths, decided by the index), a nearly flat sphere (slivers), nested spheres with an
    /// inside-out one a hair outside, a long thin mesh, and a head-on plane behind a nearer copy
    /// of opposite winding (back faces that win by a rounding-sized depth difference).
    #[test]
    fn occlusion_skipping_gives_the_single_pass_z_buffer_bit_for_bit() {
        let (mut v, f) = mesh_core::shapes::icosphere(3).into_parts();
        for (i, p) in v.iter_mut().enumerate() {
            p[0] *= 1.0 + 0.09 * (i % 3) as f64;
        }
        let flipped: Vec<[u32; 3]> = f.iter().map(|&[a, b, c]| [a, c, b]).collect();
        let open: Vec<[u32; 3]> = f
            .iter()
            .copied()
            .filter(|t| t.iter().all(|&k| v[k as usize][2] < 0.6))
            .collect();
        let mut doubled: Vec<[u32; 3]> = Vec::new();
        for (i, &[a, b, c]) in f.iter().enumerate() {
            doubled.push([a, b, c]);
            if i % 2 == 0 {
                doubled.push([a, c, b]);
            }
        }
        // Nearly flat: seen edge-on from the orbit's low views, a sheet of slivers.
        let squashed: Vec<[f64; 3]> = v.iter().map(|p| [p[0], p[1] * 1e-7, p[2]]).collect();
        // A second sphere inside the first (hidden front faces), and an inside-out one a hair
        // outside it: its back faces win by a relative 10⁻¹² in depth, over the first sphere's
        // front faces in the same tiles.
        let mut nested = v.clone();
        nested.extend(v.iter().map(|p| p.map(|c| c * 0.5)));
        nested.extend(v.iter().map(|p| p.map(|c| c * (1.0 + 1e-12))));
        let n = v.len() as u32;
        let nested_faces: Vec<[u32; 3]> = (0..3)
            .flat_map(|k| {
                let faces = if k == 2 { &flipped } else { &f };
                faces.iter().map(move |t| t.map(|i| i + k * n))
            })
            .collect();
        // Long and thin across the views' depth range: huge depth spans inside one triangle.
        let stretched: Vec<[f64; 3]> = v
            .iter()
            .map(|p| [p[0] * 0.2, p[1] * 1e3, p[2] * 0.2])
            .collect();
        let bits = |d: &[f64]| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let (w, h) = (97, 83);
        let cases = [
            (&v, &f),
            (&v, &flipped),
            (&v, &open),
            (&v, &doubled),
            (&squashed, &f),
            (&nested, &nested_faces),
            (&stretched, &f),
        ];
        for (v, faces) in cases {
            for view in crate::orbit_views(4, 25.0, 2.6, 60.0) {
                let camera = Camera::new(&view, w, h).expect("camera");
                let proj = project_vertices(&camera, v);
                let (ids, depth) = rasterize(faces, &proj, 0.5, w, h);
                let (ids_1, depth_1) = rasterize_single_pass(faces, &proj, (w, h));
                assert!(ids.iter().filter(|&&t| t != NO_TRIANGLE).count() > w * h / 100);
                assert_eq!(ids, ids_1);
                assert_eq!(bits(&depth), bits(&depth_1));
            }
        }
        // A plane seen head-on (one depth over whole tiles) behind a copy of opposite winding
        // 10⁻¹² nearer: the nearer copy must win everywhere, also when it is the back face and
        // its nearest corner lies within rounding of the tiles' farthest depth. Each winding in
        // turn is the nearer copy.
        let k = 12;
        let grid: Vec<[f64; 3]> = (0..=k)
            .flat_map(|i| (0..=k).map(move |j| [i as f64 / 6.0 - 1.0, j as f64 / 6.0 - 1.0, 0.0]))
            .collect();
        let quads: Vec<[u32; 3]> = (0..k as u32)
            .flat_map(|i| (0..k as u32).map(move |j| (i * (k as u32 + 1) + j, k as u32 + 1)))
            .flat_map(|(a, r)| [[a, a + r, a + 1], [a + 1, a + r, a + r + 1]])
            .collect();
        let view = View {
            eye: [0.0, 0.0, 3.0],
            target: [0.0; 3],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 60.0,
            light_pos: [0.0, 0.0, 3.0],
        };
        let camera = Camera::new(&view, w, h).expect("camera");
        for nearer_flipped in [false, true] {
            let mut v = grid.clone();
            v.extend(grid.iter().map(|p| [p[0], p[1], 3e-12]));
            let m = grid.len() as u32;
            let faces: Vec<[u32; 3]> = quads
                .iter()
                .map(|&t| {
                    if nearer_flipped {
                        t
                    } else {
                        [t[0], t[2], t[1]]
                    }
                })
                .chain(quads.iter().map(|&[a, b, c]| {
                    let t = if nearer_flipped { [a, c, b] } else { [a, b, c] };
                    t.map(|i| i + m)
                }))
                .collect();
            let proj = project_vertices(&camera, &v);
            let (ids, depth) = rasterize(&faces, &proj, 0.5, w, h);
            let (ids_1, depth_1) = rasterize_single_pass(&faces, &proj, (w, h));
            assert!(
                ids.iter()
                    .filter(|&&t| t >= quads.len() as u32 && t != NO_TRIANGLE)
                    .count()
                    > w * h / 10
            );
            assert_eq!(ids, ids_1);
            assert_eq!(bits(&depth), bits(&depth_1));
        }
    }

    /// [`rasterize`] runs its kernels under the run-time dispatch (AVX2 where present); with
    /// `pulp::Scalar` they are compiled for the baseline instruction set. Same ids, same depths.
    #[test]
    fn dispatched_rasterizer_equals_the_baseline_one_bit_for_bit() {
        let (mut v, f) = mesh_core::shapes::icosphere(3).into_parts();
        for (i, p) in v.iter_mut().enumerate() {
            p[2] *= 1.0 + 0.07 * (i % 5) as f64;
        }
        let (w, h) = (83, 70);
        for view in crate::orbit_views(3, 25.0, 2.6, 60.0) {
            let camera = Camera::new(&view, w, h).expect("camera");
            let proj = project_vertices(&camera, &v);
            let (ids, depth) = rasterize(&f, &proj, 0.5, w, h);
            assert!(ids.iter().filter(|&&t| t != NO_TRIANGLE).count() > w * h / 10);
            let setups = SetupAll {
                faces: &f,
                proj: &proj,
                near: 0.5,
                width: w,
                height: h,
            }
            .with_simd(pulp::Scalar);
            let all: Vec<u32> = (0..f.len() as u32).collect();
            let mut ids_b = vec![NO_TRIANGLE; w * h];
            let mut depth_b = vec![f64::INFINITY; w * h];
            for (band, (ids, depth)) in ids_b
                .chunks_mut(BAND_ROWS * w)
                .zip(depth_b.chunks_mut(BAND_ROWS * w))
                .enumerate()
            {
                RasterBand {
                    setups: &setups,
                    bin: &all,
                    row_base: band * BAND_ROWS,
                    width: w,
                    height: h,
                    ids,
                    depth,
                }
                .with_simd(pulp::Scalar);
            }
            assert_eq!(ids, ids_b);
            let bits = |d: &[f64]| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&depth), bits(&depth_b));
        }
    }
}
