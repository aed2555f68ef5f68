//! The wgpu backend: shader validation (always) and cross-checks against the CPU reference (when an
//! adapter exists; lavapipe counts). Tests that need an adapter print `SKIPPED` and return without
//! one. The assertions shared by both backends are in tests/backends.rs.
#![cfg(feature = "gpu")]

use raster_diff::cpu::raster::NO_TRIANGLE;
use raster_diff::gpu::{SHADERS, WgpuRenderer};
use raster_diff::{CpuRenderer, Images, RenderError, RenderSettings, Renderer, View, orbit_views};

#[test]
fn wgsl_shaders_validate_with_naga() {
    for (name, src) in SHADERS {
        let module = naga::front::wgsl::parse_str(src)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::empty(),
        )
        .validate(&module)
        .unwrap_or_else(|e| panic!("{name} does not validate: {e:?}"));
    }
    // Every .wgsl file in src/shaders is part of some validated module.
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/shaders");
    let mut files = 0;
    for entry in std::fs::read_dir(&dir).expect("src/shaders") {
        let path = entry.expect("entry").path();
        if path.extension().is_some_and(|e| e == "wgsl") {
            let text = std::fs::read_to_string(&path).expect("read shader");
            assert!(
                SHADERS.iter().any(|(_, s)| s.contains(&text)),
                "{} is in no validated shader module",
                path.display()
            );
            files += 1;
        }
    }
    assert!(files >= 6, "found only {files} shader files");
}

fn gpu(settings: RenderSettings) -> Option<WgpuRenderer> {
    match WgpuRenderer::new(settings) {
        Ok(g) => Some(g),
        Err(e) => {
            println!("SKIPPED: no wgpu adapter ({e})");
            None
        }
    }
}

fn norm(x: &[[f64; 3]]) -> f64 {
    x.iter().flatten().map(|a| a * a).sum::<f64>().sqrt()
}

fn rel_l2(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    let diff: Vec<[f64; 3]> = a
        .iter()
        .zip(b)
        .map(|(a, b)| [a[0] - b[0], a[1] - b[1], a[2] - b[2]])
        .collect();
    norm(&diff) / norm(a).max(1e-300)
}

/// The RGB gradient (for the wgpu backend's RGB renders) with the CPU backend's grey gradient `d`
/// in channel 0 and zeros in the others: its channel sums are `d`, exactly.
fn rgb_gradient(d: &Images) -> Images {
    assert_eq!(d.channels, 1);
    Images {
        channels: 3,
        rgb: d.rgb.iter().flat_map(|&v| [v, 0.0, 0.0]).collect(),
        ..d.clone()
    }
}

/// Pixels whose triangle id differs between the backends, and the largest image difference over
/// pixels where the id of the pixel and of its four neighbours agree (antialiasing mixes a pixel
/// with its neighbours, so a coverage difference legitimately changes them too).
fn compare_images(
    w: usize,
    h: usize,
    ids_cpu: &[u32],
    ids_gpu: &[u32],
    ic: &Images,
    ig: &Images,
) -> (usize, f32) {
    let differing = ids_cpu.iter().zip(ids_gpu).filter(|(a, b)| a != b).count();
    let same = |i: usize| ids_cpu[i] == ids_gpu[i];
    let mut max_diff = 0.0f32;
    for i in 0..ids_cpu.len() {
        let (col, row) = (i % w, (i / w) % h);
        let ok = same(i)
            && (col == 0 || same(i - 1))
            && (col + 1 == w || same(i + 1))
            && (row == 0 || same(i - w))
            && (row + 1 == h || same(i + w));
        if ok {
            max_diff = max_diff.max((ic.rgb[ic.channels * i] - ig.rgb[ig.channels * i]).abs());
        }
    }
    (differing, max_diff)
}

/// Forward and VJP against the CPU reference on an icosphere, 4 views at 96×96, with and without
/// antialiasing. Tolerances: at most 0.1 % of the pixels may see another triangle (f32 vs f64
/// projection and edge tests at centres within rounding of an edge; on lavapipe it is a handful);
/// elsewhere |Δ| ≤ 1e-4 (f32 shading is ~1e-6; antialiasing weights come from f32 screen positions);
/// the VJP of a dense random cotangent agrees to a relative L2 of 2e-3.
#[test]
fn wgpu_images_and_gradients_match_cpu() {
    for antialias in [true, false] {
        let settings = RenderSettings {
            antialias,
            ..RenderSettings::default()
        };
        let Some(mut g) = gpu(settings.clone()) else {
            return;
        };
        println!("{}", g.name());
        let (v, f) = mesh_core::shapes::icosphere(3).into_parts();
        let views = orbit_views(4, 25.0, 2.6, 90.0);
        let (w, h) = (96, 96);
        let mut c = CpuRenderer::new(settings);
        let ic = c.render(&v, &f, &views, w, h).expect("cpu render");
        let ids_cpu = c.triangle_ids().expect("state");
        let ig = g.render(&v, &f, &views, w, h).expect("gpu render");
        let ids_gpu = g.triangle_ids().expect("gpu ids");
        let covered = ids_cpu.iter().filter(|&&t| t != NO_TRIANGLE).count();
        let (differing, max_img) = compare_images(w, h, &ids_cpu, &ids_gpu, &ic, &ig);
        println!(
            "AA {antialias}: {differing} of {} pixels ({covered} covered) see another triangle; \
             max |Δ| elsewhere {max_img:e}",
            ids_gpu.len()
        );
        assert!(covered > 4000, "the sphere is visible");
        assert!(
            differing * 1000 <= ids_cpu.len(),
            "{differing} pixels differ in coverage"
        );
        assert!(max_img <= 1e-4, "images differ by {max_img}");
        let d = Images {
            rgb: (0..ic.rgb.len())
                .map(|i| ((i * 37) % 11) as f32 - 5.0)
                .collect(),
            ..ic.clone()
        };
        let gc = c.backward(&d).expect("cpu backward");
        let gg = g.backward(&rgb_gradient(&d)).expect("gpu backward");
        let rel = rel_l2(&gc, &gg);
        println!("AA {antialias}: VJP relative L2 difference {rel:e}");
        assert!(norm(&gc) > 1e-3, "non-trivial gradient");
        assert!(rel <= 2e-3, "gradients differ by {rel}");
    }
}

/// The forward is deterministic; `backward` may be called repeatedly for one render and agrees
/// with itself at the f32 rounding level (the atomic-add order varies); buffers are reused and
/// resized correctly across shape changes.
#[test]
fn wgpu_repeated_calls_and_shape_changes() {
    let Some(mut g) = gpu(RenderSettings::default()) else {
        return;
    };
    let (v, f) = mesh_core::shapes::icosphere(2).into_parts();
    let views = orbit_views(3, 25.0, 2.6, 90.0);
    let a = g.render(&v, &f, &views, 48, 40).expect("render");
    let d = Images {
        rgb: (0..a.rgb.len()).map(|i| (i % 13) as f32 - 6.0).collect(),
        ..a.clone()
    };
    let g1 = g.backward(&d).expect("backward");
    let g2 = g.backward(&d).expect("backward again");
    assert!(rel_l2(&g1, &g2) < 1e-5, "repeat: {}", rel_l2(&g1, &g2));
    // Another shape in between (more views, other size, other mesh), then the first again.
    let (v2, f2) = mesh_core::shapes::icosphere(1).into_parts();
    let views2 = orbit_views(5, 10.0, 3.0, 60.0);
    let other = g.render(&v2, &f2, &views2, 33, 17).expect("render other");
    assert_eq!((other.count, other.height, other.width), (5, 17, 33));
    assert!(
        g.backward(&d).is_err(),
        "gradient shaped for the old render"
    );
    let b = g.render(&v, &f, &views, 48, 40).expect("render again");
    assert_eq!(a, b, "forward is deterministic");
    let g3 = g.backward(&d).expect("backward");
    assert!(
        rel_l2(&g1, &g3) < 1e-5,
        "after resize: {}",
        rel_l2(&g1, &g3)
    );
}

#[test]
fn wgpu_bad_inputs_give_typed_errors() {
    let Some(mut g) = gpu(RenderSettings::default()) else {
        return;
    };
    let v = vec![[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0]];
    let view = View {
        eye: [0.0, 0.0, 2.0],
        target: [0.0; 3],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 90.0,
        light_pos: [0.0, 0.0, 2.0],
    };
    let one = std::slice::from_ref(&view);
    let d = Images {
        count: 1,
        height: 8,
        width: 8,
        channels: 3,
        rgb: vec![0.0; 192],
    };
    assert!(matches!(g.backward(&d), Err(RenderError::NoForwardState)));
    assert!(matches!(g.triangle_ids(), Err(RenderError::NoForwardState)));
    assert!(matches!(
        g.render(&v, &[[0, 1, 3]], one, 8, 8),
        Err(RenderError::InvalidInput(_))
    ));
    let nan = vec![[f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    assert!(matches!(
        g.render(&nan, &[[0, 1, 2]], one, 8, 8),
        Err(RenderError::InvalidInput(_))
    ));
    assert!(matches!(
        g.render(&v, &[[0, 1, 2]], one, 0, 8),
        Err(RenderError::InvalidInput(_))
    ));
    let bad_view = View {
        eye: [0.0; 3],
        ..view.clone()
    };
    assert!(matches!(
        g.render(&v, &[[0, 1, 2]], &[bad_view], 8, 8),
        Err(RenderError::InvalidInput(_))
    ));
    // A failed render leaves no state behind.
    assert!(matches!(g.backward(&d), Err(RenderError::NoForwardState)));
    // More pixels than one storage buffer may hold (2 × views × pixels × 4 bytes): a typed
    // device-limit error, nothing dispatched.
    let limit = g.max_storage_buffer_binding_size();
    let n_views = (limit / (8 * 1024 * 1024)) as usize + 1;
    let many = vec![view.clone(); n_views];
    assert!(
        matches!(
            g.render(&v, &[[0, 1, 2]], &many, 1024, 1024),
            Err(RenderError::DeviceLimit { .. })
        ),
        "{n_views} views at 1024² exceed a {limit}-byte binding"
    );
    let img = g.render(&v, &[[0, 1, 2]], one, 8, 8).expect("render");
    let wrong = Images {
        height: 4,
        rgb: vec![0.0; 96],
        ..img.clone()
    };
    assert!(matches!(
        g.backward(&wrong),
        Err(RenderError::InvalidInput(_))
    ));
    // The renders are RGB: a grey gradient of the right size is refused too.
    assert_eq!(img.channels, 3);
    let grey = Images {
        channels: 1,
        rgb: vec![0.0; 64],
        ..img.clone()
    };
    assert!(matches!(
        g.backward(&grey),
        Err(RenderError::InvalidInput(_))
    ));
    assert!(g.backward(&img).is_ok());
    // Empty meshes and batches render background.
    let empty = g.render(&[], &[], one, 8, 8).expect("empty mesh");
    assert!(empty.rgb.iter().all(|&x| x == 1.0));
    assert!(g.backward(&empty).expect("empty backward").is_empty());
    let none = g.render(&v, &[[0, 1, 2]], &[], 8, 8).expect("no views");
    assert_eq!(none.count, 0);
    assert_eq!(
        g.backward(&none).expect("no views backward"),
        vec![[0.0; 3]; 3]
    );
}

/// The same agreement on a non-square image whose width is not a multiple of the workgroup size
/// (70×45), 3 views at 60° fov, and two overlapping spheres (occlusion boundaries between them),
/// antialiasing on. Same tolerances as above.
#[test]
fn wgpu_matches_cpu_on_a_non_square_scene_with_occlusion() {
    let Some(mut g) = gpu(RenderSettings::default()) else {
        return;
    };
    let (mut v, mut f) = mesh_core::shapes::icosphere(3).into_parts();
    let (v2, f2) = mesh_core::shapes::icosphere(2).into_parts();
    let n = v.len() as u32;
    v.extend(
        v2.iter()
            .map(|p| [0.5 * p[0] + 0.4, 0.5 * p[1] + 0.2, 0.5 * p[2] + 1.0]),
    );
    f.extend(f2.iter().map(|t| [t[0] + n, t[1] + n, t[2] + n]));
    let views: Vec<View> = orbit_views(3, 20.0, 3.2, 60.0)
        .into_iter()
        .map(|mut view| {
            // Look from the +z side so the small sphere occludes the large one.
            view.eye[2] = view.eye[2].abs() + 1.0;
            view
        })
        .collect();
    let (w, h) = (70, 45);
    let mut c = CpuRenderer::default();
    let ic = c.render(&v, &f, &views, w, h).expect("cpu render");
    let ids_cpu = c.triangle_ids().expect("state");
    let ig = g.render(&v, &f, &views, w, h).expect("gpu render");
    let ids_gpu = g.triangle_ids().expect("gpu ids");
    let second = f.len() - f2.len();
    let occlusion_pairs = (0..ids_cpu.len())
        .filter(|&i| {
            i % w + 1 < w
                && ids_cpu[i] != NO_TRIANGLE
                && ids_cpu[i + 1] != NO_TRIANGLE
                && ((ids_cpu[i] as usize) < second) != ((ids_cpu[i + 1] as usize) < second)
        })
        .count();
    let (differing, max_img) = compare_images(w, h, &ids_cpu, &ids_gpu, &ic, &ig);
    println!(
        "{differing} of {} pixels see another triangle; max |Δ| elsewhere {max_img:e}; \
         {occlusion_pairs} horizontal pairs across the two spheres",
        ids_cpu.len()
    );
    assert!(occlusion_pairs > 10, "the scene has occlusion boundaries");
    assert!(differing * 1000 <= ids_cpu.len(), "{differing} differ");
    assert!(max_img <= 1e-4, "images differ by {max_img}");
    let d = Images {
        rgb: (0..ic.rgb.len())
            .map(|i| ((i * 53) % 17) as f32 / 8.0 - 1.0)
            .collect(),
        ..ic.clone()
    };
    let gc = c.backward(&d).expect("cpu backward");
    let gg = g.backward(&rgb_gradient(&d)).expect("gpu backward");
    let rel = rel_l2(&gc, &gg);
    println!("VJP relative L2 difference {rel:e}");
    assert!(norm(&gc) > 1e-3, "non-trivial gradient");
    assert!(rel <= 2e-3, "gradients differ by {rel}");
}
