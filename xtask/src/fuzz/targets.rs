//! Fuzz targets: each reader of user files, its work-file extension, and its seed corpus.
//!
//! A target's `run` reads one file; errors are the expected outcome for most mutants and count as
//! success. Only a panic, a hang or a memory-cap breach is a failure. Mesh targets also run
//! validation on what they read, since `stylize mesh check` and every command do.

use std::path::{Path, PathBuf};

use anyhow::Context;
use mesh_core::TriMesh;
use mesh_core::io::{PlyEncoding, write_glb, write_obj, write_off, write_ply};
use mesh_core::validate::{RepairOptions, validate};
use npy::npz::NpzReader;
use npy::{NpyArray, NpyData, parse_npy, write_npy};
use stylize::saved::SavedDeformation;

/// One reader under test.
pub struct Target {
    /// Name used by `--target` and in reports.
    pub name: &'static str,
    /// Extension of the work file (readers dispatch on it).
    pub ext: &'static str,
    /// Reads the file at the path; the result is ignored (only panics, hangs and memory count).
    pub run: fn(&Path),
}

fn mesh(path: &Path) {
    if let Ok(m) = mesh_core::io::read_mesh(path) {
        let _ = validate(&m, &RepairOptions::default());
        let _ = mesh_core::validate::repair(&m, &RepairOptions::default());
    }
}

/// The remesher on whatever a mesh file holds: read with its parts, repaired as a run does,
/// remeshed at 10 % of the diagonal (2 rounds, at most 5,000 faces, so each input stays well
/// within the time cap on a loaded machine), measured, and the parts carried over.
fn remesh(path: &Path) {
    use mesh_core::remesh::{RemeshOptions, TransferSource};
    let Ok((m, parts)) = mesh_core::io::read_mesh_with_parts(path) else {
        return;
    };
    let Ok(r) = mesh_core::validate::repair(&m, &RepairOptions::default()) else {
        return;
    };
    let (p, f) = (&r.mesh.positions, &r.mesh.faces);
    let Ok(q) = mesh_core::remesh::quality(p, f) else {
        return;
    };
    let options = RemeshOptions {
        iterations: 2,
        max_faces: 5_000,
        ..RemeshOptions::new(0.1 * q.diagonal)
    };
    if let Ok(out) = mesh_core::remesh::remesh(p, f, &options) {
        let _ = mesh_core::remesh::quality(&out.positions, &out.faces);
        let _ = mesh_core::remesh::hausdorff(&out.positions, &out.faces, p, f);
        let source = TransferSource {
            positions: p,
            faces: f,
            vertex_map: &r.vertex_map,
            face_map: &r.face_map,
        };
        let _ = mesh_core::remesh::transfer_parts(
            &parts,
            &source,
            &out.positions,
            &out.faces,
            &out.source_faces,
        );
    }
}

fn npz(path: &Path) {
    let _ = SavedDeformation::read(path);
    if let Ok(r) = NpzReader::open(path) {
        let keys: Vec<String> = r.keys().map(str::to_owned).collect();
        for k in &keys {
            let _ = r.require(k);
            let _ = r.rows3_f64(k);
            let _ = r.rows3_u32(k);
            let _ = r.string(k);
        }
    }
}

fn npy(path: &Path) {
    if let Ok(bytes) = std::fs::read(path) {
        let _ = parse_npy(&bytes);
    }
}

fn mask(path: &Path) {
    let _ = stylize_cli::cmd::apply::read_mask(path, 1000);
}

fn manifest(path: &Path) {
    let _ = stylize_cli::batch::read_manifest(path);
}

fn checkpoint(path: &Path) {
    let _ = stylize::checkpoint::Checkpoint::load(path);
}

fn config(path: &Path) {
    if let Ok(text) = std::fs::read_to_string(path) {
        let _ = stylize::config::Config::from_toml_str(&text);
    }
}

/// Region specs, one per line (also parsed back from their canonical text), as `--region`,
/// `region.specs` and manifest rows give them.
fn region(path: &Path) {
    if let Ok(bytes) = std::fs::read(path) {
        let text = String::from_utf8_lossy(&bytes);
        for line in text.lines() {
            if let Ok(spec) = mesh_core::region::RegionSpec::parse(line) {
                let _ = mesh_core::region::RegionSpec::parse(&spec.to_string());
                let _ = spec.files();
            }
        }
        let _ = mesh_core::region::RegionSpec::parse(&text);
    }
}

/// A model directory's `manifest.toml` (DeepFloyd IF and CLIP), in a folder next to the input.
fn model_manifest(path: &Path) {
    let Some(parent) = path.parent() else { return };
    let dir = parent.join("model");
    if std::fs::create_dir_all(&dir).is_err()
        || std::fs::copy(path, dir.join("manifest.toml")).is_err()
    {
        return;
    }
    let _ = diffusion_onnx::ModelDir::open(&dir);
    let _ = diffusion_onnx::clip::read_clip_manifest(&dir);
}

/// The token of the fuzzed viewer (the seeds' requests carry it, so mutants reach the routes).
const VIEW_TOKEN: &str = "0123456789abcdef0123456789abcdef";

/// The viewer the `view-http` target asks: one run directory (an octahedron's saved deformation,
/// metrics, snapshots) next to the input, opened once per child process.
fn fuzz_viewer(scratch: &Path) -> Option<std::sync::Arc<stylize_cli::view::Viewer>> {
    static VIEWER: std::sync::OnceLock<Option<std::sync::Arc<stylize_cli::view::Viewer>>> =
        std::sync::OnceLock::new();
    VIEWER
        .get_or_init(|| {
            let run = scratch.join("view-run");
            std::fs::create_dir_all(&run).ok()?;
            let m = mesh_core::shapes::octahedron();
            let verts: Vec<[f32; 3]> = m.positions.iter().map(|p| p.map(|c| c as f32)).collect();
            SavedDeformation {
                verts: verts.clone(),
                faces: m.faces.clone(),
                verts_normals: verts.clone(),
                deform_by_csd_cfg: r#"{"local_step_procrustes": {"lamb": 8.0}}"#.into(),
                dataset_cfg: "{}".into(),
                extra: Vec::new(),
            }
            .write(run.join("deformation.npz"))
            .ok()?;
            std::fs::write(run.join("run.json"), "{}").ok()?;
            std::fs::write(
                run.join("metrics.jsonl"),
                "{\"iteration\":1,\"loss\":0.5}\n{\"iteration\":2,\"loss\":0.25}\n",
            )
            .ok()?;
            let flat: Vec<f32> = verts.iter().chain(&verts).flatten().copied().collect();
            let it = NpyArray::new(vec![2], NpyData::I64(vec![0, 2])).ok()?;
            let x = NpyArray::new(vec![2, verts.len(), 3], NpyData::F32(flat)).ok()?;
            npy::npz::write_npz(run.join("snapshots.npz"), [("iterations", &it), ("x", &x)])
                .ok()?;
            stylize_cli::view::Viewer::open(&[run], VIEW_TOKEN.to_string())
                .ok()
                .map(std::sync::Arc::new)
        })
        .clone()
}

/// Raw HTTP/1 bytes as a client of `stylize view` sends them, answered in process (hyper's
/// parser, the router, the handlers; no socket).
fn view_http(path: &Path) {
    let (Some(parent), Ok(bytes)) = (path.parent(), std::fs::read(path)) else {
        return;
    };
    if let Some(viewer) = fuzz_viewer(parent) {
        let _ = stylize_cli::view::server::answer_raw(viewer, bytes);
    }
}

/// Every target, in the order they run.
pub const TARGETS: &[Target] = &[
    Target {
        name: "obj",
        ext: "obj",
        run: mesh,
    },
    Target {
        name: "off",
        ext: "off",
        run: mesh,
    },
    Target {
        name: "ply",
        ext: "ply",
        run: mesh,
    },
    Target {
        name: "gltf",
        ext: "gltf",
        run: mesh,
    },
    Target {
        name: "glb",
        ext: "glb",
        run: mesh,
    },
    Target {
        name: "remesh",
        ext: "obj",
        run: remesh,
    },
    Target {
        name: "npz",
        ext: "npz",
        run: npz,
    },
    Target {
        name: "npy",
        ext: "npy",
        run: npy,
    },
    Target {
        name: "mask",
        ext: "txt",
        run: mask,
    },
    Target {
        name: "manifest-toml",
        ext: "toml",
        run: manifest,
    },
    Target {
        name: "manifest-jsonl",
        ext: "jsonl",
        run: manifest,
    },
    Target {
        name: "checkpoint",
        ext: "json",
        run: checkpoint,
    },
    Target {
        name: "config",
        ext: "toml",
        run: config,
    },
    Target {
        name: "region",
        ext: "txt",
        run: region,
    },
    Target {
        name: "model-manifest",
        ext: "toml",
        run: model_manifest,
    },
    Target {
        name: "view-http",
        ext: "http",
        run: view_http,
    },
];

fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in bytes.chunks(3) {
        let n = (u32::from(c[0]) << 16)
            | (u32::from(*c.get(1).unwrap_or(&0)) << 8)
            | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

/// `.gltf` seeds: data-URI buffer; interleaved positions+normals with a stride; a node tree with
/// transforms and two scenes.
fn gltf_seeds(m: &TriMesh) -> Vec<Vec<u8>> {
    let mut bin = Vec::new();
    for (p, n) in m.positions.iter().zip(&m.positions) {
        for c in p.iter().chain(n) {
            bin.extend_from_slice(&(*c as f32).to_le_bytes());
        }
    }
    let idx_off = bin.len();
    for f in &m.faces {
        for &v in f {
            bin.extend_from_slice(&(v as u16).to_le_bytes());
        }
    }
    let nv = m.positions.len();
    let ni = m.faces.len() * 3;
    let uri = format!("data:application/octet-stream;base64,{}", base64(&bin));
    let common = format!(
        r#""buffers": [{{"byteLength": {}, "uri": "{uri}"}}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": {idx_off}, "byteStride": 24}},
    {{"buffer": 0, "byteOffset": {idx_off}, "byteLength": {}}}
  ],
  "accessors": [
    {{"bufferView": 0, "byteOffset": 0, "componentType": 5126, "count": {nv}, "type": "VEC3", "min": [-1, -1, -1], "max": [1, 1, 1]}},
    {{"bufferView": 0, "byteOffset": 12, "componentType": 5126, "count": {nv}, "type": "VEC3"}},
    {{"bufferView": 1, "componentType": 5123, "count": {ni}, "type": "SCALAR"}}
  ],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "NORMAL": 1}}, "indices": 2, "mode": 4}}]}}]"#,
        bin.len(),
        bin.len() - idx_off
    );
    let simple = format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}], "nodes": [{{"mesh": 0}}],
  {common}}}"#
    );
    let tree = format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 1,
  "scenes": [{{"nodes": [0]}}, {{"nodes": [1]}}],
  "nodes": [
    {{"mesh": 0}},
    {{"children": [2, 3], "translation": [0, 1, 0]}},
    {{"mesh": 0, "scale": [2, 2, 2], "children": [4]}},
    {{"mesh": 0, "matrix": [-1,0,0,0, 0,1,0,0, 0,0,1,0, 5,0,0,1]}},
    {{"mesh": 0, "rotation": [0, 0.7071068, 0, 0.7071068]}}
  ],
  {common}}}"#
    );
    vec![simple.into_bytes(), tree.into_bytes()]
}

/// Seed files for `target`: fixture files of its format plus small generated ones.
pub fn seeds(target: &str, root: &Path, scratch: &Path) -> anyhow::Result<Vec<Vec<u8>>> {
    let fx = |rel: &str| -> anyhow::Result<Vec<u8>> {
        let p = root.join(rel);
        std::fs::read(&p).with_context(|| format!("cannot read seed {}", p.display()))
    };
    let m = mesh_core::shapes::octahedron();
    let generate = |name: &str, write: &dyn Fn(&Path) -> Result<(), mesh_core::MeshError>| {
        let p: PathBuf = scratch.join(name);
        write(&p).with_context(|| format!("cannot write seed {}", p.display()))?;
        std::fs::read(&p).with_context(|| format!("cannot read seed {}", p.display()))
    };
    Ok(match target {
        "obj" => vec![
            generate("o.obj", &|p| write_obj(p, &m, None))?,
            generate("on.obj", &|p| write_obj(p, &m, Some(&m.positions)))?,
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3/1/1\nf -4 -2 -3 -1\n# c\ng x\n".to_vec(),
            fx("fixtures/meshes/bad/two_components.obj")?,
            fx("fixtures/meshes/bad/nan_coordinates.obj")?,
            fx("fixtures/meshes/bad/out_of_range_index.obj")?,
            fx("fixtures/meshes/bunny.obj")?,
        ],
        "off" => vec![
            generate("o.off", &|p| write_off(p, &m))?,
            b"COFF\n# colours\n4 2 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n0 1 0 0 0 255 255\n0 0 1 9 9 9 9\n4 0 1 2 3\n3 0 2 1 200 0 0\n".to_vec(),
            fx("fixtures/meshes/eight.off")?,
            fx("fixtures/meshes/bad/truncated.off")?,
        ],
        "ply" => vec![
            generate("a.ply", &|p| write_ply(p, &m, None, PlyEncoding::Ascii))?,
            generate("b.ply", &|p| {
                write_ply(p, &m, Some(&m.positions), PlyEncoding::BinaryLittleEndian)
            })?,
            b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nelement face 1\nproperty list uchar uint vertex_indices\nelement edge 0\nend_header\n\0\0\0\0\0\0\0\0\0\0\0\0\x01?\x80\0\0\0\0\0\0\0\0\0\0\x02\0\0\0\0?\x80\0\0\0\0\0\0\x03\x03\0\0\0\0\0\0\0\x01\0\0\0\x02".to_vec(),
            fx("fixtures/meshes/bone.ply")?,
        ],
        "remesh" => vec![
            generate("o.obj", &|p| write_obj(p, &m, None))?,
            // Two groups, a needle fan and a zero-area face.
            b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 0.5 0\nv 0.5 0.5 1\ng left\nf 1 2 5\nf 2 3 5\ng right\nf 3 4 5\nf 4 1 5\nf 1 2 6\nf 2 3 6\nf 3 4 6\nf 4 1 6\nf 1 5 1\n".to_vec(),
            fx("fixtures/meshes/bad/two_components.obj")?,
            generate("eight.obj", &|p| {
                let eight = mesh_core::io::read_mesh(root.join("fixtures/meshes/eight.off"))?;
                write_obj(p, &eight, None)
            })?,
        ],
        "gltf" => gltf_seeds(&m),
        "glb" => vec![
            generate("o.glb", &|p| write_glb(p, &m, None))?,
            generate("on.glb", &|p| write_glb(p, &m, Some(&m.positions)))?,
        ],
        "npz" => {
            let saved = SavedDeformation {
                verts: m.positions.iter().map(|p| p.map(|c| c as f32)).collect(),
                faces: m.faces.clone(),
                verts_normals: m.positions.iter().map(|p| p.map(|c| c as f32)).collect(),
                deform_by_csd_cfg: r#"{"local_step_procrustes": {"lamb": 8.0}}"#.into(),
                dataset_cfg: "{}".into(),
                extra: vec![(
                    "seed".into(),
                    NpyArray::new(vec![], NpyData::I64(vec![3])).map_err(anyhow::Error::msg)?,
                )],
            };
            let p = scratch.join("s.npz");
            saved
                .write(&p)
                .with_context(|| format!("cannot write seed {}", p.display()))?;
            vec![
                std::fs::read(&p).with_context(|| format!("cannot read seed {}", p.display()))?,
                fx("fixtures/meshes/numpy_tet.npz")?,
                fx("fixtures/meshes/bunny_targets.npz")?,
            ]
        }
        "npy" => vec![
            write_npy(&NpyArray::f32_rows3(&[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])),
            write_npy(&NpyArray::i64_rows3(&[[0, 1, 2]])),
            write_npy(&NpyArray::scalar_str("{\"lamb\": 8.0}")),
            write_npy(
                &NpyArray::new(vec![2, 2], NpyData::I32(vec![1, -2, 3, 4]))
                    .map_err(anyhow::Error::msg)?,
            ),
            write_npy(
                &NpyArray::new(vec![3], NpyData::Bool(vec![true, false, true]))
                    .map_err(anyhow::Error::msg)?,
            ),
        ],
        "mask" => vec![b"# free vertices\n0\n1\n\n17\n999\n".to_vec()],
        "manifest-toml" => vec![
            b"[[run]]\nmesh = \"bunny.obj\"\nout = \"runs/a\"\nstyle = \"cube\"\nseed = 3\noverrides = [\"run.iterations=10\"]\n\n[[run]]\nmesh = \"/abs/cow.off\"\nout = \"runs/b\"\nprompt = \"a lego cow\"\nnegative_prompt = \"blurry\"\n".to_vec(),
        ],
        "manifest-jsonl" => vec![
            b"# rows\n{\"mesh\": \"bunny.obj\", \"out\": \"runs/a\", \"style\": \"cube\", \"seed\": 3}\n\n{\"mesh\": \"cow.off\", \"out\": \"runs/b\", \"prompt\": \"a lego cow\", \"overrides\": [\"run.iterations=10\"]}\n".to_vec(),
            // Odd encodings: a byte-order mark (also mid-file), CRLF line ends, UTF-16.
            b"\xEF\xBB\xBF{\"mesh\": \"a.obj\", \"out\": \"r/a\", \"style\": \"exemplar:e.obj\"}\r\n\xEF\xBB\xBF{\"mesh\": \"b.obj\", \"out\": \"r/b\", \"style\": \"cube\", \"region\": [\"not:vertices:v.txt\"], \"overrides\": [\"region.specs=[\\\"vertices:w.txt\\\"]\"]}\r\n".to_vec(),
            b"\xFF\xFE{\0\"\0m\0e\0s\0h\0\"\0:\0 \0\"\0a\0\"\0}\0\n\0".to_vec(),
        ],
        "region" => vec![
            b"box:-1,-1,-1,0,1,1\nsphere:0,0.5,0,0.25\nvertices:head.txt\npart:seat\nproperty:label>=3\nnot:not:part:legs\n not : box:0,0,0,1,1,1\n".to_vec(),
            format!("{}part:x\n", "not:".repeat(70)).into_bytes(),
        ],
        "model-manifest" => vec![
            fx("fixtures/models/tiny-if/manifest.toml")?,
            fx("fixtures/models/tiny-if-fp16/manifest.toml")?,
            fx("fixtures/models/tiny-clip/manifest.toml")?,
        ],
        "view-http" => {
            let t = VIEW_TOKEN;
            [
                format!("GET /{t}/api/items HTTP/1.1\r\nHost: x\r\n\r\n"),
                format!("GET /{t}/api/items/0/result?lambda=5 HTTP/1.1\r\nHost: x\r\n\r\nGET /{t}/api/items/0/source HTTP/1.1\r\nHost: x\r\n\r\n"),
                format!("GET /{t}/api/items/0/download?lambda=1&format=obj HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"),
                format!("GET /{t}/api/items/0/files/..%2Frun.json HTTP/1.1\r\nHost: x\r\n\r\n"),
                format!("GET /{t}/api/items/0/replay/2?faces=1 HTTP/1.1\r\nHost: x\r\n\r\nGET /{t}/api/items/0/metrics HTTP/1.1\r\nHost: x\r\n\r\n"),
                format!("POST /{t}/api/items HTTP/1.1\r\nHost: x\r\nContent-Length: 5\r\n\r\nhello"),
                "GET /wrong/api/items HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\n0\r\n\r\n".to_string(),
            ]
            .into_iter()
            .map(String::into_bytes)
            .collect()
        }
        "checkpoint" => vec![checkpoint_seed(scratch)?],
        "config" => vec![
            fx("fixtures/configs/quick-style.toml")?,
            fx("fixtures/configs/reference.toml")?,
            fx("fixtures/configs/tall.toml")?,
        ],
        other => anyhow::bail!("no seeds for target {other}"),
    })
}

/// A valid checkpoint, written the way the CLI writes it.
fn checkpoint_seed(scratch: &Path) -> anyhow::Result<Vec<u8>> {
    use rand::SeedableRng;
    let c = stylize::checkpoint::Checkpoint {
        version: stylize::checkpoint::CHECKPOINT_VERSION,
        iteration: 3,
        state: stylize::checkpoint::CheckpointState {
            x: vec![[0.5, -0.25, 1.0], [1e-300, 2.0, -3.5]],
            adam: optim::AdamState {
                step: 3,
                m: vec![0.0, 1.0, -2.0, 0.5, 0.25, 1e-9],
                v: vec![1e-300, 2.0, 3.0, 4.0, 5.0, 6.0],
            },
            rng: rand_chacha::ChaCha8Rng::seed_from_u64(9),
            config_toml: "[run]\nseed = 9\n".into(),
        },
        identity: Some(stylize::identity::TaskIdentity {
            fields: [
                ("mesh_sha256", "00ff"),
                ("objective", "style:cube"),
                ("darap.lambda", "8"),
            ]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect(),
        }),
    };
    let p = scratch.join("checkpoint.json");
    c.save_atomic(&p)?;
    Ok(std::fs::read(&p)?)
}
