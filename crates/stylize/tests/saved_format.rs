//! The saved-deformation `.npz` against the golden file and by round trips (moved from mesh-core
//! with the format).

use mesh_core::{TriMesh, io::read_mesh, normalize::side2_cube};
use npy::npz::{NpzReader, NpzWriter};
use npy::{NpyArray, NpyData, NpyError};
use stylize::saved::{SavedDeformation, SavedError};

mod common {
    use std::path::PathBuf;

    /// A file of `fixtures/meshes/`.
    pub fn fixture(name: &str) -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/meshes")
            .join(name)
    }
}

#[test]
fn golden_saved_deformation_reads_with_reference_keys_and_config() {
    let s = SavedDeformation::read(common::fixture("bunny_targets.npz")).expect("golden npz reads");
    assert_eq!(s.verts.len(), 1839);
    assert_eq!(s.faces.len(), 3674);
    assert_eq!(s.verts_normals.len(), 1839);
    assert_eq!(s.lambda(), Some(8.0));
    assert!(s.pin_first_vertex());
    assert!(s.normalize_target_normals());
    assert_eq!(
        s.arap_energy_type().as_deref(),
        Some("spokes_and_rims_mine")
    );
    assert_eq!(s.solve_method().as_deref(), Some("arap"));
    assert!(s.dataset_cfg.contains("bunny.obj"));
    assert!(s.extra.is_empty());
    // Target normals are documented as not unit length.
    let lens: Vec<f32> = s
        .verts_normals
        .iter()
        .map(|n| (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt())
        .collect();
    assert!(lens.iter().any(|&l| (l - 1.0).abs() > 1e-3));
}

#[test]
fn golden_verts_are_the_side2_normalized_bunny_obj_in_file_order() {
    // Independent check of both readers: the npz's `verts` are bunny.obj after §1.1, as f32,
    // vertex for vertex (so the OBJ reader must keep file order).
    let s = SavedDeformation::read(common::fixture("bunny_targets.npz")).expect("golden npz reads");
    let mut m = read_mesh(common::fixture("bunny.obj")).expect("bunny.obj reads");
    side2_cube(&mut m.positions);
    assert_eq!(m.positions.len(), s.verts.len());
    for (p, v) in m.positions.iter().zip(&s.verts) {
        for k in 0..3 {
            assert!((p[k] - f64::from(v[k])).abs() < 1e-6, "{p:?} vs {v:?}");
        }
    }
    assert_eq!(m.faces, s.faces);
}

#[test]
fn saved_deformation_round_trips_with_extra_keys_kept() {
    let mut s =
        SavedDeformation::read(common::fixture("bunny_targets.npz")).expect("golden npz reads");
    s.set_extra(
        "format_version",
        NpyArray::new(vec![], NpyData::I64(vec![1])).expect("0-d"),
    )
    .expect("extra key");
    s.set_extra("rotation_rule", NpyArray::scalar_str("gis"))
        .expect("extra key");
    s.set_extra(
        "seed",
        NpyArray::new(vec![], NpyData::I64(vec![42])).expect("0-d"),
    )
    .expect("extra key");
    assert!(s.set_extra("verts", NpyArray::scalar_str("x")).is_err());
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("nested/missing/out.npz");
    s.write(&path).expect("writes, creating parent folders");
    let back = SavedDeformation::read(&path).expect("reads back");
    assert_eq!(back, s);
    assert_eq!(
        back.extra("rotation_rule").and_then(|a| a.as_str()),
        Some("gis")
    );
    // On-disk dtypes are the reference's: f4, i8, 0-d <U.
    let r = NpzReader::open(&path).expect("opens");
    let keys: Vec<&str> = r.keys().collect();
    assert_eq!(
        &keys[..5],
        &[
            "verts",
            "faces",
            "verts_normals",
            "deform_by_csd_cfg",
            "dataset_cfg"
        ]
    );
    assert!(matches!(
        r.get("faces").map(|a| &a.data),
        Some(NpyData::I64(_))
    ));
    assert!(matches!(
        r.get("verts").map(|a| &a.data),
        Some(NpyData::F32(_))
    ));
    assert_eq!(r.get("deform_by_csd_cfg").map(|a| a.shape.len()), Some(0));
}

#[test]
fn written_npy_headers_match_the_golden_files_bytes() {
    // The golden file was written by numpy; our header for the same array must be identical.
    let r = NpzReader::open(common::fixture("bunny_targets.npz")).expect("opens");
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("same.npz");
    let mut w = NpzWriter::create(&path).expect("create");
    for k in ["verts", "faces", "deform_by_csd_cfg"] {
        w.add(k, r.get(k).expect("present")).expect("add");
    }
    w.finish().expect("finish");
    // Compare the raw .npy bytes inside both zips.
    let raw = |p: &std::path::Path, k: &str| -> Vec<u8> {
        use std::io::Read;
        let mut z = zip::ZipArchive::new(std::fs::File::open(p).expect("open")).expect("zip");
        let mut e = z.by_name(&format!("{k}.npy")).expect("entry");
        let mut b = Vec::new();
        e.read_to_end(&mut b).expect("read");
        b
    };
    for k in ["verts", "faces", "deform_by_csd_cfg"] {
        assert_eq!(
            raw(&path, k),
            raw(&common::fixture("bunny_targets.npz"), k),
            "{k}.npy differs"
        );
    }
}

#[test]
fn missing_keys_wrong_shapes_and_garbage_are_clear_errors() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("partial.npz");
    let mut w = NpzWriter::create(&p).expect("create");
    w.add("verts", &NpyArray::f32_rows3(&[[0.0; 3]]))
        .expect("add");
    w.add(
        "faces",
        &NpyArray::new(vec![3], NpyData::I64(vec![0, 0, 0])).expect("1-d"),
    )
    .expect("add");
    assert!(
        w.add("verts", &NpyArray::f32_rows3(&[])).is_err(),
        "duplicate key"
    );
    w.finish().expect("finish");
    let e = SavedDeformation::read(&p).expect_err("bad input must be rejected");
    assert!(
        matches!(&e, SavedError::Npy(NpyError::Array { key, .. }) if key == "faces"),
        "{e}"
    );
    assert!(e.to_string().contains("(N, 3)"), "{e}");

    let garbage = dir.path().join("garbage.npz");
    std::fs::write(&garbage, b"this is not a zip file at all").expect("write");
    let e = SavedDeformation::read(&garbage).expect_err("bad input must be rejected");
    assert!(e.to_string().contains("garbage.npz"), "{e}");

    // A truncated copy of the golden file.
    let bytes = std::fs::read(common::fixture("bunny_targets.npz")).expect("read");
    let cut = dir.path().join("cut.npz");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).expect("write");
    assert!(SavedDeformation::read(&cut).is_err());

    let e = SavedDeformation::read(dir.path().join("absent.npz"))
        .expect_err("bad input must be rejected");
    assert!(matches!(e, SavedError::Npy(NpyError::Io { .. })));
}

#[test]
fn out_of_range_face_in_saved_file_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s = SavedDeformation {
        verts: vec![[0.0; 3]; 3],
        faces: vec![[0, 1, 3]],
        verts_normals: vec![[0.0, 0.0, 1.0]; 3],
        deform_by_csd_cfg: "{}".into(),
        dataset_cfg: "{}".into(),
        extra: vec![],
    };
    let p = dir.path().join("bad.npz");
    s.write(&p).expect("writing does not validate");
    let e = SavedDeformation::read(&p).expect_err("bad input must be rejected");
    assert!(e.to_string().contains("face 0"), "{e}");
    // Defaults when the config lacks the keys.
    assert_eq!(s.lambda(), None);
    assert!(s.pin_first_vertex());
    // A recorded λ that is not a finite number ≥ 0 is no λ, and the reason names it.
    let mut s = s;
    for (cfg, why) in [
        (
            r#"{"local_step_procrustes": {"lamb": -1.5}}"#,
            "lamb = -1.5",
        ),
        (
            r#"{"local_step_procrustes": {"lamb": "8"}}"#,
            "lamb = \"8\"",
        ),
        (
            r#"{"local_step_procrustes": {"lamb": NaN}}"#,
            "not valid JSON",
        ),
        ("{}", "records no λ"),
    ] {
        s.deform_by_csd_cfg = cfg.into();
        assert_eq!(s.lambda(), None, "{cfg}");
        let e = s.recorded_lambda().expect_err("no usable λ");
        assert!(e.contains(why), "{cfg}: {e}");
    }
    s.deform_by_csd_cfg = r#"{"local_step_procrustes": {"lamb": 0}}"#.into();
    assert_eq!(s.recorded_lambda(), Ok(0.0));
}

#[test]
fn numpy_savez_compressed_file_with_other_dtypes_reads() {
    // Written by NumPy 2.4.6 with np.savez_compressed (deflated, zip64 entries); generator in
    // fixtures/meshes/README.md. Faces are int32 and normals float64 here; both convert.
    let s = SavedDeformation::read(common::fixture("numpy_tet.npz")).expect("reads");
    assert_eq!(s.verts[3], [0.0, 0.0, 1.0]);
    assert_eq!(s.faces, vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]);
    assert_eq!(s.verts_normals[1], [1.0, 0.5, 0.25]);
    assert_eq!(s.lambda(), Some(5.5));
    assert!(!s.pin_first_vertex());
    assert!(!s.normalize_target_normals());
    assert_eq!(s.dataset_cfg, "{\"name\": \"tétraèdre ✓\"}");
    let extra = |k: &str| s.extra(k).expect("extra key kept").clone();
    assert_eq!(
        extra("mask").data,
        NpyData::Bool(vec![true, false, true, true])
    );
    let grid = extra("grid");
    assert_eq!(grid.shape, vec![2, 3, 4]);
    assert_eq!(grid.data, NpyData::U8((0..24).collect()));
    assert_eq!(extra("big").data, NpyData::I64(vec![-(1 << 40), 1 << 40]));
    assert_eq!(
        (extra("seed").shape.len(), extra("seed").data),
        (0, NpyData::U32(vec![42]))
    );
}

#[test]
fn npz_reads_only_the_entries_it_needs() {
    use std::io::Write;
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("s.npz");
    let tet = TriMesh::new(
        vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    );
    let saved = SavedDeformation {
        verts: tet.positions.iter().map(|p| p.map(|c| c as f32)).collect(),
        faces: tet.faces.clone(),
        verts_normals: vec![[0.0, 0.0, 1.0]; 4],
        deform_by_csd_cfg: "{}".into(),
        dataset_cfg: "{}".into(),
        extra: vec![("seed".into(), NpyArray::scalar_str("3"))],
    };
    saved.write(&path).expect("writes");
    // Append a deflated extra entry that declares 32 MiB and whose stream is garbage: inflating
    // it would fail (and, were it a real 3 GB stream, cost 3 GB).
    {
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&path)
            .expect("open");
        let mut zip = zip::ZipWriter::new_append(file).expect("append");
        let opts = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated);
        zip.start_file("junk.npy", opts).expect("start");
        zip.write_all(&vec![0u8; 32 << 20]).expect("write");
        zip.finish().expect("finish");
    }
    let back = SavedDeformation::read(&path).expect("reads without the junk");
    assert_eq!(back.verts, saved.verts);
    assert!(
        back.extra("junk").is_none(),
        "large extra entries are not loaded"
    );
    assert!(back.extra("seed").is_some());
    let r = NpzReader::open(&path).expect("opens");
    assert_eq!(r.declared_size("junk"), Some(32 << 20));
    assert!(r.require("verts").is_ok());
}

/// A file of `fixtures/golden/`.
fn golden(name: &str) -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/golden")
        .join(name)
}

#[test]
fn ready_layer_reapplies_the_golden_deformation() {
    let path = golden("bunny_targets.npz");
    let s = SavedDeformation::read(&path).expect("golden npz reads");
    let mut ready = s.ready_layer_as_saved(&path).expect("layer builds");
    assert_eq!(ready.rest.faces, s.faces);
    for (lambda, file) in [
        (8.0, "bunny_lambda8_gis.obj"),
        (5.0, "bunny_lambda5_gis.obj"),
    ] {
        let deformed = ready.at_lambda(lambda).expect("forward");
        let want = read_mesh(golden(file)).expect("golden result reads");
        let worst = deformed
            .positions
            .iter()
            .zip(&want.positions)
            .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
            .fold(0.0, f64::max);
        assert!(worst < 1e-9, "λ = {lambda}: {worst}");
    }
    // Every vertex free is the same as no region at all.
    let mut whole = s.ready_layer(&path, 8.0, None).expect("layer builds");
    let free = vec![true; s.verts.len()];
    let mut all_free = s.ready_layer(&path, 8.0, None).expect("layer builds");
    all_free
        .set_region(
            &s,
            &path,
            stylize::saved::Region::Free {
                free,
                feather: None,
            },
        )
        .expect("region");
    let a = whole.at_lambda(8.0).expect("forward").positions;
    let b = all_free.at_lambda(8.0).expect("forward").positions;
    assert_eq!(a, b);
}

#[test]
fn ready_layer_refuses_unnormalized_targets_and_bad_rules() {
    let path = golden("bunny_targets.npz");
    let mut s = SavedDeformation::read(&path).expect("golden npz reads");
    s.set_extra("rotation_rule", NpyArray::scalar_str("kabsch"))
        .expect("extra");
    let e = s.ready_layer(&path, 8.0, None).expect_err("unknown rule");
    assert!(matches!(e, SavedError::RotationRule { .. }), "{e}");
    let mut cfg: serde_json::Value =
        serde_json::from_str(&s.deform_by_csd_cfg).expect("golden config is JSON");
    cfg["local_step_procrustes"]["normalize_target_normals"] = false.into();
    s.deform_by_csd_cfg = cfg.to_string();
    assert!(!s.normalize_target_normals());
    let e = s.ready_layer(&path, 8.0, None).expect_err("unnormalized");
    assert!(matches!(e, SavedError::NotNormalized { .. }), "{e}");
    assert!(
        e.to_string().ends_with(
            "`normalize_target_normals` is false; only normalized target normals are supported"
        ),
        "{e}"
    );
}
