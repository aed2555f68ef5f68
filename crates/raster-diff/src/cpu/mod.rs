//! The CPU reference backend: exact, deterministic, multithreaded over views (rayon).
//!
//! Geometry is f64 throughout; the grey (one-channel) f32 images of the [`Renderer`] trait are the
//! f64 values cast at the end. [`CpuRenderer::render_f64`] / [`CpuRenderer::backward_f64`] are the
//! same render and backward in f64, for gradient checks.
//!
//! Gradient accumulation is deterministic: every view accumulates into its own buffers, which are
//! summed in view order; within a view pixels are visited in a fixed order.

pub mod antialias;
pub(crate) mod lanes;
pub mod math;
pub mod normals;
pub mod raster;
pub mod shading;
pub(crate) mod simd;

use std::borrow::Cow;

use glam::DVec3;
use rayon::prelude::*;

use crate::{Images, RenderError, Renderer, View};
use antialias::Blend;
use raster::{Camera, NO_TRIANGLE};

/// Options of the CPU renderer.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Silhouette antialiasing (and its visibility gradient). On by default.
    pub antialias: bool,
    /// Near-plane depth; triangles with a vertex nearer than this are not drawn. Default 0.5.
    pub near: f64,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            antialias: true,
            near: 0.5,
        }
    }
}

/// Background value (white) composited behind the mesh.
pub const BACKGROUND: f64 = 1.0;

struct ViewState {
    camera: Camera,
    ids: Vec<u32>,
    /// Colour before antialiasing (background = 1).
    colour: Vec<f64>,
    blends: Vec<Blend>,
}

struct ForwardState {
    vertices: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
    normals: Vec<DVec3>,
    normal_sums: Vec<DVec3>,
    views: Vec<ViewState>,
    width: usize,
    height: usize,
}

struct AdjacencyCache {
    faces: Vec<[u32; 3]>,
    adjacency: Vec<[u32; 3]>,
}

/// The CPU reference renderer. Keeps the state of its most recent render for `backward`.
#[derive(Default)]
pub struct CpuRenderer {
    /// Rendering options.
    pub settings: RenderSettings,
    state: Option<ForwardState>,
    /// Face adjacency of the last face list (faces rarely change between renders).
    adjacency_cache: Option<AdjacencyCache>,
}

impl std::fmt::Debug for CpuRenderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CpuRenderer")
            .field("settings", &self.settings)
            .finish_non_exhaustive()
    }
}

pub(crate) fn validate(
    vertices: &[[f64; 3]],
    faces: &[[u32; 3]],
    width: usize,
    height: usize,
) -> Result<(), RenderError> {
    if width == 0 || height == 0 {
        return Err(RenderError::InvalidInput(format!(
            "image size {width}×{height} is empty"
        )));
    }
    if width.checked_mul(height).is_none_or(|n| n > (1 << 28)) {
        return Err(RenderError::InvalidInput(format!(
            "image size {width}×{height} is too large"
        )));
    }
    if let Some(i) = vertices
        .iter()
        .position(|v| v.iter().any(|c| !c.is_finite()))
    {
        return Err(RenderError::InvalidInput(format!(
            "vertex {i} has a non-finite coordinate"
        )));
    }
    let n = vertices.len();
    if let Some((fi, f)) = faces
        .iter()
        .enumerate()
        .find(|(_, f)| f.iter().any(|&v| v as usize >= n))
    {
        return Err(RenderError::InvalidInput(format!(
            "face {fi} {f:?} indexes past the {n} vertices"
        )));
    }
    Ok(())
}

impl CpuRenderer {
    /// A renderer with the given settings.
    pub fn new(settings: RenderSettings) -> Self {
        Self {
            settings,
            state: None,
            adjacency_cache: None,
        }
    }

    fn adjacency(&mut self, faces: &[[u32; 3]]) -> Vec<[u32; 3]> {
        match &self.adjacency_cache {
            Some(c) if c.faces.as_slice() == faces => c.adjacency.clone(),
            _ => {
                let adjacency = antialias::face_adjacency(faces);
                self.adjacency_cache = Some(AdjacencyCache {
                    faces: faces.to_vec(),
                    adjacency: adjacency.clone(),
                });
                adjacency
            }
        }
    }

    /// Renders the grey value of every pixel, `(view, row, column)` row-major, in f64: the
    /// [`Renderer::render`] of this backend before its values are rounded to f32.
    pub fn render_f64(
        &mut self,
        vertices: &[[f64; 3]],
        faces: &[[u32; 3]],
        views: &[View],
        width: usize,
        height: usize,
    ) -> Result<Vec<f64>, RenderError> {
        let mut grey = Vec::new();
        self.render_into(
            vertices,
            faces,
            views,
            (width, height),
            1,
            &mut grey,
            |g, d| d.copy_from_slice(g),
        )?;
        Ok(grey)
    }

    /// The render, written view by view (in parallel) into `out`: `values_per_pixel` values of
    /// type `T` per pixel, `(view, row, column, value)`, which `write` makes from one view's
    /// antialiased grey values. `out` is replaced (left empty on error); keeps the state for
    /// `backward`.
    #[allow(clippy::too_many_arguments)]
    fn render_into<T: Copy + Default + Send + Sync>(
        &mut self,
        vertices: &[[f64; 3]],
        faces: &[[u32; 3]],
        views: &[View],
        (width, height): (usize, usize),
        values_per_pixel: usize,
        out: &mut Vec<T>,
        write: impl Fn(&[f64], &mut [T]) + Sync,
    ) -> Result<(), RenderError> {
        self.state = None;
        out.clear();
        validate(vertices, faces, width, height)?;
        let cameras = views
            .iter()
            .map(|v| Camera::new(v, width, height))
            .collect::<Result<Vec<_>, _>>()?;
        let adjacency = if self.settings.antialias {
            self.adjacency(faces)
        } else {
            Vec::new()
        };
        let face_raw = normals::face_normals_raw(vertices, faces);
        let (vnormals, sums) = normals::smooth_normals(vertices, faces, &face_raw);
        let settings = &self.settings;
        let per_view = width * height * values_per_pixel;
        // Sized (and zeroed) in parallel; every value is then written by its view.
        out.par_extend(rayon::iter::repeat_n(T::default(), views.len() * per_view));
        let states: Vec<ViewState> = cameras
            .into_par_iter()
            .zip(out.par_chunks_mut(per_view))
            .map(|(camera, dst)| {
                let proj = raster::project_vertices(&camera, vertices);
                let (ids, depth) = raster::rasterize(faces, &proj, settings.near, width, height);
                let colour = simd::dispatch(ShadeView {
                    camera: &camera,
                    vertices,
                    faces,
                    vnormals: &vnormals,
                    ids: &ids,
                });
                let blends = if settings.antialias {
                    let blends = antialias::find_blends(
                        vertices, faces, &adjacency, &face_raw, &camera, &proj, &ids, &depth,
                    );
                    // Most pixels keep their colour: write the view, then the blended few.
                    write(&colour, dst);
                    for (t, value) in antialias::blended_pixels(&colour, &blends) {
                        let at = t as usize * values_per_pixel;
                        write(&[value], &mut dst[at..at + values_per_pixel]);
                    }
                    blends
                } else {
                    write(&colour, dst);
                    Vec::new()
                };
                ViewState {
                    camera,
                    ids,
                    colour,
                    blends,
                }
            })
            .collect();
        self.state = Some(ForwardState {
            vertices: vertices.to_vec(),
            faces: faces.to_vec(),
            normals: vnormals,
            normal_sums: sums,
            views: states,
            width,
            height,
        });
        Ok(())
    }

    /// VJP of the most recent render ([`render_f64`](Self::render_f64) or
    /// [`Renderer::render`]) with dL/d(grey) in f64, `(view, row, column)`: → dL/dvertices.
    pub fn backward_f64(&self, d_grey: &[f64]) -> Result<Vec<[f64; 3]>, RenderError> {
        let mut out = self.backward_many_f64(&[d_grey])?;
        Ok(out.pop().unwrap_or_default())
    }

    /// [`backward_f64`](Self::backward_f64) for several gradients of the same render at once:
    /// one dL/dvertices per entry of `d_greys`, in order. The per-pixel work that does not depend
    /// on the gradient (the fragment, the shading and its Jacobian) is done once and shared, so
    /// two gradients cost much less than two calls. Each result is what a call with that gradient
    /// alone returns, bit for bit. (The loop's path is the trait's
    /// [`backward_many`](Renderer::backward_many), which takes `f32` grey images.)
    pub fn backward_many_f64(&self, d_greys: &[&[f64]]) -> Result<Vec<Vec<[f64; 3]>>, RenderError> {
        let st = self.state.as_ref().ok_or(RenderError::NoForwardState)?;
        let npix = st.width * st.height;
        check_grey_lengths(d_greys.iter().map(|d| d.len()), st.views.len() * npix)?;
        Ok(backward_views(st, d_greys.len(), |g, vi| {
            Cow::Borrowed(&d_greys[g][vi * npix..(vi + 1) * npix])
        }))
    }
    /// Bytes of the state kept from the most recent render for `backward` (0 when there is none):
    /// the vertex and face copies, smooth normals and their unnormalized sums, and per view the
    /// triangle ids (4 B per pixel), the colour before antialiasing (8 B per pixel) and the
    /// antialiasing blends. Measured for the "Renderer backward state" decision in
    /// `docs/architecture.md`.
    pub fn backward_state_bytes(&self) -> usize {
        use std::mem::size_of;
        self.state.as_ref().map_or(0, |s| {
            let per_view: usize = s
                .views
                .iter()
                .map(|v| {
                    size_of::<ViewState>()
                        + v.ids.len() * size_of::<u32>()
                        + v.colour.len() * size_of::<f64>()
                        + v.blends.len() * size_of::<antialias::Blend>()
                })
                .sum();
            size_of::<ForwardState>()
                + s.vertices.len() * size_of::<[f64; 3]>()
                + s.faces.len() * size_of::<[u32; 3]>()
                + (s.normals.len() + s.normal_sums.len()) * size_of::<DVec3>()
                + per_view
        })
    }

    /// Visible triangle per pixel of the most recent render, `(view, row, column)`
    /// ([`raster::NO_TRIANGLE`] for background).
    pub fn triangle_ids(&self) -> Option<Vec<u32>> {
        self.state
            .as_ref()
            .map(|s| s.views.iter().flat_map(|v| v.ids.iter().copied()).collect())
    }
}

/// Checks that every dL/d(grey) has one value per pixel of the last render (`pixels`).
fn check_grey_lengths(
    lengths: impl Iterator<Item = usize>,
    pixels: usize,
) -> Result<(), RenderError> {
    for len in lengths {
        if len != pixels {
            return Err(RenderError::InvalidInput(format!(
                "gradient has {len} values, the last render had {pixels}"
            )));
        }
    }
    Ok(())
}

/// One vertex's adjoints for one gradient, accumulated by the backward pass over a view's pixels:
/// `[dL/dx, dL/dn]` (position, smooth normal). A view's records are vertex-major, gradient `g` of
/// vertex `v` at `v·count + g`, so a pixel's contributions to a corner, for every gradient, land in
/// one run of `48·count` bytes instead of `2·count` separate arrays (measured: the backward a few
/// per cent faster; the same additions in the same order, so the same bits).
type VertexAdjoint = [DVec3; 2];

/// The backward pass of the render kept in `st` for `count` gradients: `d_view(g, v)` is
/// gradient `g`'s dL/d(grey) on view `v`, `(row, column)`, asked for inside the view's parallel
/// task. Per view, the per-pixel work that does not depend on the gradient (the fragment, the
/// shading and its Jacobian) is done once for all of them.
fn backward_views<'a>(
    st: &ForwardState,
    count: usize,
    d_view: impl Fn(usize, usize) -> Cow<'a, [f64]> + Sync,
) -> Vec<Vec<[f64; 3]>> {
    let nv = st.vertices.len();
    // Per view: the vertices' adjoint records for every gradient (see `VertexAdjoint`).
    let per_view: Vec<Vec<VertexAdjoint>> = st
        .views
        .par_iter()
        .enumerate()
        .map(|(vi, view)| {
            let mut acc: Vec<VertexAdjoint> = vec![[DVec3::ZERO; 2]; nv * count];
            let d_colours: Vec<Cow<'_, [f64]>> = (0..count)
                .map(|g| {
                    antialias::apply_adjoint(&view.colour, &view.blends, d_view(g, vi), |v, d| {
                        acc[v * count + g][0] += d
                    })
                })
                .collect();
            simd::dispatch(AccumulateView {
                st,
                view,
                d_colours: &d_colours,
                acc: &mut acc,
            });
            acc
        })
        .collect();
    // The gradients' sums over the views and normal adjoints are independent: one task each.
    (0..count)
        .into_par_iter()
        .map(|g| {
            let mut dx = vec![DVec3::ZERO; nv];
            let mut dn = vec![DVec3::ZERO; nv];
            for view in &per_view {
                let records = view[g..].iter().step_by(count);
                for (v, [x, n]) in records.enumerate() {
                    dx[v] += *x;
                    dn[v] += *n;
                }
            }
            normals::smooth_normals_adjoint(
                &st.vertices,
                &st.faces,
                &st.normals,
                &st.normal_sums,
                &dn,
                &mut dx,
            );
            dx.into_iter().map(Into::into).collect()
        })
        .collect()
}

/// One view's shading, as a [`simd::dispatch`] kernel: the colour of every pixel before
/// antialiasing ([`BACKGROUND`] where no triangle is visible).
struct ShadeView<'a> {
    camera: &'a Camera,
    vertices: &'a [[f64; 3]],
    faces: &'a [[u32; 3]],
    vnormals: &'a [DVec3],
    ids: &'a [u32],
}

impl pulp::WithSimd for ShadeView<'_> {
    type Output = Vec<f64>;
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> Vec<f64> {
        let mut colour = vec![BACKGROUND; self.ids.len()];
        let mut triangle = TriangleCache::default();
        let rays = PixelRays::new(self.camera);
        let width = self.camera.width;
        for (row, (ids, colour)) in self
            .ids
            .chunks_exact(width)
            .zip(colour.chunks_exact_mut(width))
            .enumerate()
        {
            for (col, (&t, c)) in ids.iter().zip(colour).enumerate() {
                if t != NO_TRIANGLE {
                    let tri =
                        triangle.get(self.camera, self.vertices, self.faces, self.vnormals, t);
                    *c = shading::shade(tri, rays.get(self.camera, row, col));
                }
            }
        }
        colour
    }
}

/// Up to [`lanes::LANES`] pixels gathered for the lane-wise shading Jacobian (the backward's
/// per-pixel work; the forward shading stays one pixel at a time, where gathering the lanes costs
/// more than it saves, measured): each one's triangle (copied:
/// the [`TriangleCache`] slot may be reused by the next pixel) and centre ray, and its (pixel
/// index, triangle id), in the order they were pushed. Entries past `len` are stale, computed on
/// and ignored.
#[derive(Default)]
struct PixelBatch {
    triangles: [shading::Triangle; lanes::LANES],
    rays: [DVec3; lanes::LANES],
    pixels: [(usize, u32); lanes::LANES],
    len: usize,
}

impl PixelBatch {
    /// Adds a pixel; returns whether the batch is now full.
    #[inline(always)]
    fn push(&mut self, triangle: &shading::Triangle, ray: DVec3, pixel: usize, t: u32) -> bool {
        self.triangles[self.len] = *triangle;
        self.rays[self.len] = ray;
        self.pixels[self.len] = (pixel, t);
        self.len += 1;
        self.len == lanes::LANES
    }

    /// Adds the pixels' shading Jacobians, scaled by each gradient's dL/dc, to that gradient's
    /// (dL/dx, dL/dn) of the triangles' corners, pixel after pixel in the order they were pushed
    /// (the order of the sums); empties the batch.
    #[inline(always)]
    fn accumulate(
        &mut self,
        faces: &[[u32; 3]],
        d_colours: &[Cow<'_, [f64]>],
        acc: &mut [VertexAdjoint],
    ) {
        if self.len == 0 {
            return;
        }
        let (dc_dx, dc_dn, some) = shading::shade_jacobian_lanes(
            &shading::TriangleLanes::gather(&self.triangles),
            lanes::V::gather(self.rays),
        );
        for (l, &(i, t)) in self.pixels[..self.len].iter().enumerate() {
            if !some[l] {
                continue;
            }
            let f = faces[t as usize];
            let count = d_colours.len();
            for (g, d_colour) in d_colours.iter().enumerate() {
                let dc = d_colour[i];
                if dc == 0.0 {
                    continue;
                }
                for k in 0..3 {
                    let [dx, dn] = &mut acc[f[k] as usize * count + g];
                    *dx += dc_dx[k].lane(l) * dc;
                    *dn += dc_dn[k].lane(l) * dc;
                }
            }
        }
        self.len = 0;
    }
}

/// One view's share of the backward pass, as a [`simd::dispatch`] kernel: per covered pixel the
/// shading's Jacobian, scaled by each gradient's dL/dc and added to that gradient's
/// (dL/dx, dL/dn) of the triangle's corners. The Jacobians are evaluated four pixels at a time
/// ([`PixelBatch`], [`shading::shade_jacobian_lanes`]: bit for bit the scalar
/// [`shading::shade_jacobian`]) and added pixel after pixel in row-major order, as one at a time.
struct AccumulateView<'a, 'b> {
    st: &'a ForwardState,
    view: &'a ViewState,
    d_colours: &'a [Cow<'b, [f64]>],
    acc: &'a mut [VertexAdjoint],
}

impl pulp::WithSimd for AccumulateView<'_, '_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let Self {
            st,
            view,
            d_colours,
            acc,
        } = self;
        let mut triangle = TriangleCache::default();
        let rays = PixelRays::new(&view.camera);
        let width = view.camera.width;
        let mut batch = PixelBatch::default();
        for (row, ids) in view.ids.chunks_exact(width).enumerate() {
            for (col, &t) in ids.iter().enumerate() {
                let i = row * width + col;
                if t == NO_TRIANGLE || d_colours.iter().all(|d| d[i] == 0.0) {
                    continue;
                }
                let tri = triangle.get(&view.camera, &st.vertices, &st.faces, &st.normals, t);
                if batch.push(tri, rays.get(&view.camera, row, col), i, t) {
                    batch.accumulate(&st.faces, d_colours, acc);
                }
            }
        }
        batch.accumulate(&st.faces, d_colours, acc);
    }
}

/// Slots of a [`TriangleCache`] (a power of two).
const TRIANGLE_SLOTS: usize = 512;

/// The shading's per-triangle part of recently asked-for triangles, direct-mapped by triangle id
/// (`id mod TRIANGLE_SLOTS`). Pixels come in rows and a triangle covers short runs of
/// neighbouring pixels on several rows, so most of a row's triangles were already met on the row
/// above; a collision only means computing the part again.
struct TriangleCache {
    /// (triangle id, its per-triangle part); [`NO_TRIANGLE`] marks an empty slot (the renderer
    /// never asks for it).
    slots: Vec<(u32, shading::Triangle)>,
}

impl Default for TriangleCache {
    fn default() -> Self {
        Self {
            slots: vec![(NO_TRIANGLE, shading::Triangle::default()); TRIANGLE_SLOTS],
        }
    }
}

impl TriangleCache {
    /// The per-triangle part of triangle `t` seen from `camera`.
    #[inline(always)]
    fn get(
        &mut self,
        camera: &Camera,
        vertices: &[[f64; 3]],
        faces: &[[u32; 3]],
        vnormals: &[DVec3],
        t: u32,
    ) -> &shading::Triangle {
        let (id, triangle) = &mut self.slots[t as usize % TRIANGLE_SLOTS];
        if *id != t {
            let f = faces[t as usize];
            *triangle = shading::Triangle::new(
                f.map(|v| DVec3::from(vertices[v as usize])),
                f.map(|v| vnormals[v as usize]),
                camera.eye,
                camera.light,
            );
            *id = t;
        }
        triangle
    }
}

/// The centre rays of one view's pixels, [`Camera::pixel_ray`] at `(col + 0.5, row + 0.5)`, with
/// its two per-pixel divisions done once per column and once per row: the same operations on the
/// same values, so the same bits (tested), without two divisions per pixel.
struct PixelRays {
    /// `(col + 0.5 − cx) / k` per column.
    col: Vec<f64>,
    /// `(row + 0.5 − cy) / k` per row.
    row: Vec<f64>,
}

impl PixelRays {
    #[inline(always)]
    fn new(camera: &Camera) -> Self {
        Self {
            col: (0..camera.width)
                .map(|c| (c as f64 + 0.5 - camera.cx) / camera.k)
                .collect(),
            row: (0..camera.height)
                .map(|r| (r as f64 + 0.5 - camera.cy) / camera.k)
                .collect(),
        }
    }

    /// World direction of the centre ray of the pixel at (`row`, `col`).
    #[inline(always)]
    fn get(&self, camera: &Camera, row: usize, col: usize) -> DVec3 {
        camera.right * self.col[col] - camera.up * self.row[row] + camera.forward
    }
}

impl Renderer for CpuRenderer {
    fn name(&self) -> String {
        format!("cpu ({} threads)", rayon::current_num_threads())
    }

    /// Grey images (one channel): the shading's value of every pixel, rounded to f32.
    fn render(
        &mut self,
        vertices: &[[f64; 3]],
        faces: &[[u32; 3]],
        views: &[View],
        width: usize,
        height: usize,
    ) -> Result<Images, RenderError> {
        let mut grey = Vec::new();
        self.render_into(
            vertices,
            faces,
            views,
            (width, height),
            image_batch::GREY,
            &mut grey,
            |g, d| {
                for (d, &g) in d.iter_mut().zip(g) {
                    *d = g as f32;
                }
            },
        )?;
        Ok(Images::with_channels(
            views.len(),
            height,
            width,
            image_batch::GREY,
            grey,
        )?)
    }

    fn backward(&mut self, d_images: &Images) -> Result<Vec<[f64; 3]>, RenderError> {
        let mut out = self.backward_many(&[d_images])?;
        Ok(out.pop().unwrap_or_default())
    }

    /// One pass over the pixels for all the gradients (see [`CpuRenderer::backward_many_f64`]),
    /// each grey gradient widened to `f64` view by view inside the parallel pass (the
    /// antialiasing's adjoint then works in that buffer).
    fn backward_many(&mut self, d_images: &[&Images]) -> Result<Vec<Vec<[f64; 3]>>, RenderError> {
        let st = self.state.as_ref().ok_or(RenderError::NoForwardState)?;
        for d in d_images {
            d.check_gradient_shape(st.views.len(), st.height, st.width, image_batch::GREY)?;
        }
        Ok(backward_views(st, d_images.len(), |g, vi| {
            Cow::Owned(d_images[g].view(vi).iter().map(|&v| f64::from(v)).collect())
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pulp::WithSimd;

    #[test]
    fn pixel_ray_tables_give_the_camera_rays_bit_for_bit() {
        for view in crate::orbit_views(4, 35.0, 2.2, 47.0) {
            let camera = Camera::new(&view, 37, 29).expect("camera");
            let rays = PixelRays::new(&camera);
            for row in 0..29 {
                for col in 0..37 {
                    let want = camera.pixel_ray(col as f64 + 0.5, row as f64 + 0.5);
                    let got = rays.get(&camera, row, col);
                    assert_eq!(
                        got.to_array().map(f64::to_bits),
                        want.to_array().map(f64::to_bits)
                    );
                }
            }
        }
    }

    /// The per-pixel loops run under [`simd::dispatch`] (AVX2 where the CPU has it); calling a
    /// kernel with `pulp::Scalar` compiles it for the baseline instruction set. Same bits.
    #[test]
    fn dispatched_pixel_loops_equal_the_baseline_ones_bit_for_bit() {
        let (mut v, f) = mesh_core::shapes::icosphere(3).into_parts();
        for (i, p) in v.iter_mut().enumerate() {
            p[1] *= 1.0 + 0.05 * (i % 7) as f64;
        }
        let views = crate::orbit_views(3, 20.0, 3.0, 50.0);
        let mut r = CpuRenderer::default();
        let img = r.render(&v, &f, &views, 96, 80).expect("render");
        let d: Vec<f64> = (0..img.rgb.len())
            .map(|i| ((i % 13) as f64 - 6.0) * 1e-2)
            .collect();
        let dispatched = r.backward_f64(&d).expect("backward");
        let st = r.state.as_ref().expect("state");
        let bits = |x: &[DVec3]| {
            x.iter()
                .map(|p| p.to_array().map(f64::to_bits))
                .collect::<Vec<_>>()
        };
        let npix = st.width * st.height;
        let mut total = (vec![DVec3::ZERO; v.len()], vec![DVec3::ZERO; v.len()]);
        for (vi, view) in st.views.iter().enumerate() {
            assert!(view.ids.iter().filter(|&&t| t != NO_TRIANGLE).count() > npix / 10);
            let colour = ShadeView {
                camera: &view.camera,
                vertices: &st.vertices,
                faces: &st.faces,
                vnormals: &st.normals,
                ids: &view.ids,
            }
            .with_simd(pulp::Scalar);
            assert_eq!(
                colour.iter().map(|c| c.to_bits()).collect::<Vec<_>>(),
                view.colour.iter().map(|c| c.to_bits()).collect::<Vec<_>>()
            );
            let proj = raster::project_vertices(&view.camera, &st.vertices);
            let near = RenderSettings::default().near;
            let (ids, depth) = raster::rasterize(&st.faces, &proj, near, st.width, st.height);
            assert_eq!(ids, view.ids);
            let face_raw = normals::face_normals_raw(&st.vertices, &st.faces);
            let blends = antialias::FindBlends {
                vertices: &st.vertices,
                faces: &st.faces,
                adjacency: &antialias::face_adjacency(&st.faces),
                face_raw: &face_raw,
                camera: &view.camera,
                proj: &proj,
                ids: &ids,
                depth: &depth,
            }
            .with_simd(pulp::Scalar);
            assert!(!blends.is_empty());
            let key = |b: &[Blend]| {
                b.iter()
                    .map(|b| {
                        let d = b.d_alpha.map(|d| d.to_array().map(f64::to_bits));
                        (b.target, b.source, b.edge, b.alpha.to_bits(), d)
                    })
                    .collect::<Vec<_>>()
            };
            assert_eq!(key(&blends), key(&view.blends));
            let mut acc = vec![[DVec3::ZERO; 2]; v.len()];
            let d_colour = antialias::apply_adjoint(
                &view.colour,
                &view.blends,
                Cow::Borrowed(&d[vi * npix..(vi + 1) * npix]),
                |k, g| acc[k][0] += g,
            );
            AccumulateView {
                st,
                view,
                d_colours: &[d_colour],
                acc: &mut acc,
            }
            .with_simd(pulp::Scalar);
            for k in 0..v.len() {
                total.0[k] += acc[k][0];
                total.1[k] += acc[k][1];
            }
        }
        normals::smooth_normals_adjoint(
            &st.vertices,
            &st.faces,
            &st.normals,
            &st.normal_sums,
            &total.1,
            &mut total.0,
        );
        let dispatched: Vec<DVec3> = dispatched.into_iter().map(DVec3::from).collect();
        assert!(
            dispatched.iter().all(|g| g.is_finite()) && dispatched.iter().any(|g| g.length() > 0.0)
        );
        assert_eq!(bits(&total.0), bits(&dispatched));
    }
}
