//! `stylize view`'s HTTP API, in process (the router answers requests without a socket) and end to
//! end (the binary prints its URL and answers on 127.0.0.1): token, status codes, path traversal
//! (plain, percent-encoded, symbolic links), λ validation, runs still being written, downloads.

#![allow(clippy::unwrap_used)]

use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use axum::body::Body;
use axum::http::{Request, StatusCode};
use stylize_cli::view::{Viewer, server::router};
use tower::ServiceExt;

const TOKEN: &str = "0123456789abcdef0123456789abcdef";

fn golden(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/golden")
        .join(name)
}

/// A complete run directory holding the golden bunny's saved deformation (λ = 8).
fn complete_run(parent: &Path, name: &str) -> PathBuf {
    let dir = parent.join(name);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(golden("bunny_targets.npz"), dir.join("deformation.npz")).unwrap();
    std::fs::write(dir.join("run.json"), "{}").unwrap();
    std::fs::write(dir.join("metrics.jsonl"), "{\"iteration\":1}\n").unwrap();
    dir
}

struct Reply {
    status: StatusCode,
    headers: axum::http::HeaderMap,
    body: Vec<u8>,
}

impl Reply {
    fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }
}

async fn get(app: &axum::Router, uri: &str) -> Reply {
    let req = Request::builder().uri(uri).body(Body::empty()).unwrap();
    let resp = app.clone().oneshot(req).await.unwrap();
    let status = resp.status();
    let headers = resp.headers().clone();
    let body = axum::body::to_bytes(resp.into_body(), usize::MAX)
        .await
        .unwrap()
        .to_vec();
    Reply {
        status,
        headers,
        body,
    }
}

fn app(paths: &[PathBuf]) -> axum::Router {
    router(Arc::new(Viewer::open(paths, TOKEN.to_string()).unwrap()))
}

fn rt() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .build()
        .unwrap()
}

/// Splits a framed response: (header JSON, payload).
fn unframe(body: &[u8]) -> (serde_json::Value, &[u8]) {
    let len = u32::from_le_bytes(body[..4].try_into().unwrap()) as usize;
    let head = serde_json::from_slice(&body[4..4 + len]).unwrap();
    (head, &body[4 + len.div_ceil(4) * 4..])
}

fn f32s(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

#[test]
fn every_request_needs_the_token() {
    let dir = tempfile::tempdir().unwrap();
    let app = app(&[complete_run(dir.path(), "run")]);
    rt().block_on(async {
        assert_eq!(
            get(&app, &format!("/{TOKEN}/")).await.status,
            StatusCode::OK
        );
        for uri in [
            "/",
            "/api/items",
            "/index.html",
            "/static/app.js",
            "/api/items/0/files/run.json",
            "/0123456789abcdef0123456789abcdee/api/items",
            "/0123456789abcdef0123456789abcdef0/api/items",
            "/0123456789ABCDEF0123456789ABCDEF/api/items",
            &format!("/x/{TOKEN}/api/items"),
            &format!("/api/items?token={TOKEN}"),
        ] {
            let r = get(&app, uri).await;
            assert_eq!(r.status, StatusCode::FORBIDDEN, "{uri}: {}", r.text());
            assert!(r.text().contains("token"), "{uri}: {}", r.text());
        }
        // Inside the token's space, unknown paths are 404.
        let r = get(&app, &format!("/{TOKEN}/nothing")).await;
        assert_eq!(r.status, StatusCode::NOT_FOUND);
        // The bare token redirects to the page (relative URLs need the slash).
        let r = get(&app, &format!("/{TOKEN}")).await;
        assert!(r.status.is_redirection(), "{}", r.status);
    });
}

#[test]
fn only_get_is_served() {
    let dir = tempfile::tempdir().unwrap();
    let app = app(&[complete_run(dir.path(), "run")]);
    rt().block_on(async {
        for method in ["POST", "PUT", "DELETE"] {
            let req = Request::builder()
                .method(method)
                .uri(format!("/{TOKEN}/api/items/0/result?lambda=3"))
                .body(Body::empty())
                .unwrap();
            let resp = app.clone().oneshot(req).await.unwrap();
            assert_eq!(resp.status(), StatusCode::METHOD_NOT_ALLOWED, "{method}");
        }
    });
}

#[test]
fn page_and_vendored_three_js_are_embedded() {
    let dir = tempfile::tempdir().unwrap();
    let app = app(&[complete_run(dir.path(), "run")]);
    rt().block_on(async {
        let page = get(&app, &format!("/{TOKEN}/")).await;
        assert!(page.text().contains("static/app.js"));
        assert!(
            page.headers["content-type"]
                .to_str()
                .unwrap()
                .starts_with("text/html")
        );
        for asset in [
            "static/app.js",
            "static/style.css",
            "static/vendor/three/three.module.js",
            "static/vendor/three/three.core.js",
            "static/vendor/three/OrbitControls.js",
            "static/vendor/three/LICENSE",
        ] {
            let r = get(&app, &format!("/{TOKEN}/{asset}")).await;
            assert_eq!(r.status, StatusCode::OK, "{asset}");
            assert!(r.body.len() > 100, "{asset}");
        }
        let r = get(&app, &format!("/{TOKEN}/static/../static/app.js")).await;
        assert_ne!(r.status, StatusCode::OK);
        let r = get(&app, &format!("/{TOKEN}/static/nope.js")).await;
        assert_eq!(r.status, StatusCode::NOT_FOUND);
    });
}

#[test]
fn items_source_and_result_at_lambda() {
    let dir = tempfile::tempdir().unwrap();
    let run = complete_run(dir.path(), "run");
    let app = app(&[run, golden("bunny.obj")]);
    rt().block_on(async {
        let r = get(&app, &format!("/{TOKEN}/api/items")).await;
        assert_eq!(r.status, StatusCode::OK);
        let items: serde_json::Value = serde_json::from_slice(&r.body).unwrap();
        assert_eq!(items[0]["kind"], "run");
        assert_eq!(items[0]["status"], "complete");
        assert_eq!(items[0]["lambda"], 8.0);
        assert_eq!(items[0]["has_deformation"], true);
        assert_eq!(items[1]["kind"], "mesh");

        let r = get(&app, &format!("/{TOKEN}/api/items/0/source")).await;
        assert_eq!(r.status, StatusCode::OK);
        let (head, payload) = unframe(&r.body);
        let (n, m) = (
            head["vertices"].as_u64().unwrap() as usize,
            head["faces"].as_u64().unwrap() as usize,
        );
        assert_eq!(payload.len(), 12 * n + 12 * m);
        let source = f32s(&payload[..12 * n]);

        // At the saved λ the result is the golden apply output (f32 on the wire).
        let r = get(&app, &format!("/{TOKEN}/api/items/0/result?lambda=8")).await;
        assert_eq!(r.status, StatusCode::OK, "{}", r.text());
        let (head, payload) = unframe(&r.body);
        assert_eq!(payload.len(), 12 * n);
        let at8 = f32s(payload);
        let golden8 = mesh_core::io::read_mesh(golden("bunny_lambda8_gis.obj")).unwrap();
        let err = golden8
            .positions
            .iter()
            .flatten()
            .zip(&at8)
            .map(|(a, b)| (a - *b as f64).abs())
            .fold(0.0, f64::max);
        assert!(err < 1e-5, "max deviation from golden {err}");
        assert_eq!(head["lambda"], 8.0);
        for key in ["volume_ratio", "area_ratio_mean", "flipped_fraction"] {
            assert!(head[key].as_f64().unwrap().is_finite(), "{key}: {head}");
        }
        // Another λ gives another shape and other identity metrics.
        let r = get(&app, &format!("/{TOKEN}/api/items/0/result?lambda=2.5")).await;
        let (head2, payload2) = unframe(&r.body);
        assert_ne!(f32s(payload2), at8);
        assert_ne!(head2["volume_ratio"], head["volume_ratio"]);
        // λ = 0 keeps (almost) the source (up to recentring/rescaling and the gis rule's
        // few non-identity vertices): closer to it than λ = 8 is.
        let r = get(&app, &format!("/{TOKEN}/api/items/0/result?lambda=0")).await;
        let (_, payload0) = unframe(&r.body);
        let dist = |a: &[f32]| -> f64 {
            a.iter()
                .zip(&source)
                .map(|(x, y)| ((x - y) as f64).powi(2))
                .sum::<f64>()
        };
        assert!(dist(&f32s(payload0)) < dist(&at8));

        // A mesh item has a source but no result.
        let r = get(&app, &format!("/{TOKEN}/api/items/1/source")).await;
        assert_eq!(r.status, StatusCode::OK);
        let r = get(&app, &format!("/{TOKEN}/api/items/1/result?lambda=3")).await;
        assert_eq!(r.status, StatusCode::BAD_REQUEST);
        let r = get(&app, &format!("/{TOKEN}/api/items/7/source")).await;
        assert_eq!(r.status, StatusCode::NOT_FOUND);
        let r = get(&app, &format!("/{TOKEN}/api/items/-1/source")).await;
        assert_eq!(r.status, StatusCode::BAD_REQUEST);
    });
}

#[test]
fn collapsing_lambda_is_reported_in_the_result_header() {
    let dir = tempfile::tempdir().unwrap();
    let app = app(&[complete_run(dir.path(), "run")]);
    rt().block_on(async {
        let r = get(&app, &format!("/{TOKEN}/api/items/0/result?lambda=20")).await;
        let (head, _) = unframe(&r.body);
        let warnings = head["warnings"].as_array().unwrap();
        assert!(!warnings.is_empty(), "{head}");
        // λ = 20 on the golden bunny also crosses itself: the figures and the faces to highlight.
        let x = &head["intersections"];
        let new_pairs = x["new_pairs"].as_u64().unwrap();
        assert!(new_pairs > 0, "{head}");
        assert_eq!(x["source_pairs"], 0, "{head}");
        let faces = head["intersecting_faces"].as_array().unwrap();
        assert_eq!(faces.len() as u64, x["faces"].as_u64().unwrap(), "{head}");
        assert_eq!(
            head["new_intersecting_faces"].as_array().unwrap().len() as u64,
            x["new_faces"].as_u64().unwrap()
        );
        assert!(
            faces
                .iter()
                .all(|f| f.as_u64().unwrap() < head["faces"].as_u64().unwrap())
        );
        assert!(
            warnings
                .iter()
                .any(|w| w.as_str().unwrap().contains("new self-intersecting")),
            "{head}"
        );
        let r = get(&app, &format!("/{TOKEN}/api/items/0/result?lambda=5")).await;
        let (head, _) = unframe(&r.body);
        assert!(head["warnings"].as_array().unwrap().is_empty(), "{head}");
        assert_eq!(head["intersections"]["new_pairs"], 0, "{head}");
        assert!(head["intersecting_faces"].as_array().unwrap().is_empty());
    });
}

#[test]
fn max_safe_is_the_strongest_safe_lambda_up_to_upper() {
    let dir = tempfile::tempdir().unwrap();
    let app = app(&[complete_run(dir.path(), "run"), golden("bunny.obj")]);
    rt().block_on(async {
        let j = json(&app, &format!("/{TOKEN}/api/items/0/max-safe?upper=20")).await;
        let lambda = j["lambda"].as_f64().unwrap();
        let hi = j["first_unsafe"].as_f64().unwrap();
        // λ = 8 is safe and λ = 10 is not on the golden bunny (docs/cli.md, "λ sanity").
        assert!(
            (8.0..10.0).contains(&lambda) && hi > lambda && hi <= 1.01 * lambda,
            "{j}"
        );
        let r = get(
            &app,
            &format!("/{TOKEN}/api/items/0/result?lambda={lambda}"),
        )
        .await;
        assert!(
            unframe(&r.body).0["warnings"]
                .as_array()
                .unwrap()
                .is_empty()
        );
        let r = get(&app, &format!("/{TOKEN}/api/items/0/result?lambda={hi}")).await;
        assert!(
            !unframe(&r.body).0["warnings"]
                .as_array()
                .unwrap()
                .is_empty()
        );
        // Everything safe up to a small upper end: the upper end itself.
        let j = json(&app, &format!("/{TOKEN}/api/items/0/max-safe?upper=3")).await;
        assert_eq!(
            (j["lambda"].as_f64(), j["first_unsafe"].as_f64()),
            (Some(3.0), None),
            "{j}"
        );
        for bad in ["0", "-1", "NaN", "1000", "x"] {
            let r = get(&app, &format!("/{TOKEN}/api/items/0/max-safe?upper={bad}")).await;
            assert_eq!(r.status, 400, "upper={bad}: {}", r.text());
        }
        let r = get(&app, &format!("/{TOKEN}/api/items/1/max-safe?upper=5")).await;
        assert_eq!(r.status, 404, "a mesh has no λ: {}", r.text());
    });
}

#[test]
fn bad_lambdas_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let app = app(&[complete_run(dir.path(), "run")]);
    rt().block_on(async {
        for l in [
            "NaN", "nan", "inf", "-inf", "-1", "-0.001", "100.5", "1e300", "1e400", "abc", "",
            "8%00", "0x10",
        ] {
            let r = get(&app, &format!("/{TOKEN}/api/items/0/result?lambda={l}")).await;
            assert_eq!(r.status, StatusCode::BAD_REQUEST, "λ = {l}: {}", r.text());
            let r = get(
                &app,
                &format!("/{TOKEN}/api/items/0/download?lambda={l}&format=obj"),
            )
            .await;
            assert_eq!(r.status, StatusCode::BAD_REQUEST, "download λ = {l}");
        }
        let r = get(&app, &format!("/{TOKEN}/api/items/0/result")).await;
        assert_eq!(r.status, StatusCode::BAD_REQUEST);
        // The bounds themselves are accepted.
        for l in ["0", "100"] {
            let r = get(&app, &format!("/{TOKEN}/api/items/0/result?lambda={l}")).await;
            assert_eq!(r.status, StatusCode::OK, "λ = {l}: {}", r.text());
        }
    });
}

#[test]
fn downloads_are_meshes_at_the_chosen_lambda() {
    let dir = tempfile::tempdir().unwrap();
    let app = app(&[complete_run(dir.path(), "bunny run")]);
    rt().block_on(async {
        for format in ["obj", "ply", "glb"] {
            let r = get(
                &app,
                &format!("/{TOKEN}/api/items/0/download?lambda=5&format={format}"),
            )
            .await;
            assert_eq!(r.status, StatusCode::OK, "{format}: {}", r.text());
            let disposition = r.headers["content-disposition"].to_str().unwrap();
            assert!(
                disposition.contains(&format!("bunny_run_lambda5.{format}")),
                "{disposition}"
            );
            let path = dir.path().join(format!("got.{format}"));
            std::fs::write(&path, &r.body).unwrap();
            let got = mesh_core::io::read_mesh(&path).unwrap();
            let golden5 = mesh_core::io::read_mesh(golden("bunny_lambda5_gis.obj")).unwrap();
            assert_eq!(got.faces, golden5.faces);
            let err = got
                .positions
                .iter()
                .flatten()
                .zip(golden5.positions.iter().flatten())
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(err < 1e-5, "{format}: {err}");
        }
        let r = get(
            &app,
            &format!("/{TOKEN}/api/items/0/download?lambda=5&format=exe"),
        )
        .await;
        assert_eq!(r.status, StatusCode::BAD_REQUEST);
    });
}

#[test]
fn downloads_come_in_the_runs_input_frame_unless_asked_for_the_normalized_one() {
    use stylize::frame::{InputFrame, OutputFrame, UpAxis};
    let dir = tempfile::tempdir().unwrap();
    let run = complete_run(dir.path(), "framed");
    // The golden run as if its input had been z-up, in millimetres, far from the origin.
    let npz = run.join("deformation.npz");
    let mut saved = stylize::saved::SavedDeformation::read(&npz).unwrap();
    let frame = InputFrame::from_normalization(UpAxis::PosZ, [120.0, 40.0, -2000.0], 1.0 / 500.0);
    saved
        .set_input_frame(&frame, OutputFrame::Input, UpAxis::PosZ)
        .unwrap();
    saved.write(&npz).unwrap();
    let plain = complete_run(dir.path(), "plain");
    let app = app(&[run, plain]);
    let download = |item: usize, query: &str| {
        let app = app.clone();
        let uri = format!("/{TOKEN}/api/items/{item}/download?lambda=5&format=obj{query}");
        let path = dir.path().join(format!("got{item}{}.obj", query.len()));
        let r = rt().block_on(async { get(&app, &uri).await });
        assert_eq!(r.status, StatusCode::OK, "{uri}: {}", r.text());
        r.body.pipe_to(&path)
    };
    let own = download(0, "");
    let normalized = download(0, "&frame=normalized");
    let golden5 = mesh_core::io::read_mesh(golden("bunny_lambda5_gis.obj")).unwrap();
    let rest = saved.rest_positions();
    let expected = frame.place_result(&normalized.positions, &rest, true);
    let err = |a: &[[f64; 3]], b: &[[f64; 3]]| {
        a.iter()
            .flatten()
            .zip(b.iter().flatten())
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
    };
    assert!(err(&normalized.positions, &golden5.positions) < 1e-5);
    assert!(
        err(&own.positions, &expected) < 1e-9,
        "{}",
        err(&own.positions, &expected)
    );
    assert!(err(&own.positions, &normalized.positions) > 1.0);
    // A run that records no input frame: normalized by default, an explicit `input` refused.
    let plain_default = download(1, "");
    assert!(err(&plain_default.positions, &golden5.positions) < 1e-5);
    rt().block_on(async {
        for (query, status) in [
            ("&frame=input", StatusCode::BAD_REQUEST),
            ("&frame=sideways", StatusCode::BAD_REQUEST),
        ] {
            let r = get(
                &app,
                &format!("/{TOKEN}/api/items/1/download?lambda=5&format=obj{query}"),
            )
            .await;
            assert_eq!(r.status, status, "{query}: {}", r.text());
        }
    });
}

/// Writes downloaded bytes to a file and reads them as a mesh.
trait PipeTo {
    fn pipe_to(self, path: &Path) -> mesh_core::TriMesh;
}

impl PipeTo for Vec<u8> {
    fn pipe_to(self, path: &Path) -> mesh_core::TriMesh {
        std::fs::write(path, &self).unwrap();
        mesh_core::io::read_mesh(path).unwrap()
    }
}

#[test]
fn files_are_served_from_inside_the_run_only() {
    let dir = tempfile::tempdir().unwrap();
    let run = complete_run(dir.path(), "run");
    std::fs::write(dir.path().join("secret.txt"), "TOP-SECRET-CONTENT").unwrap();
    std::fs::create_dir_all(run.join("previews")).unwrap();
    std::fs::write(run.join("previews/iter_000001.png"), "png").unwrap();
    std::os::unix::fs::symlink(dir.path().join("secret.txt"), run.join("escape.txt")).unwrap();
    std::os::unix::fs::symlink(dir.path(), run.join("parent")).unwrap();
    std::os::unix::fs::symlink("/etc/passwd", run.join("passwd")).unwrap();
    std::os::unix::fs::symlink(run.join("run.json"), run.join("inside.json")).unwrap();
    let app = app(&[run]);
    rt().block_on(async {
        let base = format!("/{TOKEN}/api/items/0/files");
        let r = get(&app, &format!("{base}/run.json")).await;
        assert_eq!(r.status, StatusCode::OK);
        assert_eq!(r.text(), "{}");
        let r = get(&app, &format!("{base}/previews/iter_000001.png")).await;
        assert_eq!(r.status, StatusCode::OK);
        assert_eq!(r.headers["content-type"], "image/png");
        // A link that stays inside the run is fine.
        let r = get(&app, &format!("{base}/inside.json")).await;
        assert_eq!(r.status, StatusCode::OK);
        for attempt in [
            "../secret.txt",
            "%2e%2e/secret.txt",
            "%2E%2E%2Fsecret.txt",
            "previews/../../secret.txt",
            "previews%2F..%2F..%2Fsecret.txt",
            "./run.json",
            "%2Fetc%2Fpasswd",
            "/etc/passwd",
            "escape.txt",
            "parent/secret.txt",
            "passwd",
            "previews",
            "nothing.png",
            "run.json%00.png",
        ] {
            let r = get(&app, &format!("{base}/{attempt}")).await;
            assert!(
                matches!(
                    r.status,
                    StatusCode::BAD_REQUEST | StatusCode::NOT_FOUND | StatusCode::FORBIDDEN
                ),
                "{attempt}: {} {}",
                r.status,
                r.text()
            );
            assert!(!r.text().contains("TOP-SECRET"), "{attempt}: {}", r.text());
            assert!(!r.text().contains("root:"), "{attempt}");
        }
    });
}

#[test]
fn a_run_still_being_written_answers_409_and_appears_when_complete() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("running");
    std::fs::create_dir_all(&run).unwrap();
    std::fs::write(run.join("task.json"), "{}").unwrap();
    std::fs::write(run.join("run.lock"), "{}").unwrap();
    let app = app(std::slice::from_ref(&run));
    rt().block_on(async {
        let r = get(&app, &format!("/{TOKEN}/api/items")).await;
        let items: serde_json::Value = serde_json::from_slice(&r.body).unwrap();
        assert_eq!(items[0]["status"], "running");
        assert_eq!(items[0]["has_deformation"], false);
        for what in ["source", "result?lambda=3", "download?lambda=3&format=obj"] {
            let r = get(&app, &format!("/{TOKEN}/api/items/0/{what}")).await;
            assert_eq!(r.status, StatusCode::CONFLICT, "{what}: {}", r.text());
            assert!(r.text().contains("deformation.npz"), "{}", r.text());
        }
        // A damaged result is an error naming the file, and the server keeps serving.
        std::fs::write(run.join("deformation.npz"), b"PK\x03\x04 not really").unwrap();
        let r = get(&app, &format!("/{TOKEN}/api/items/0/result?lambda=3")).await;
        assert_eq!(r.status, StatusCode::INTERNAL_SERVER_ERROR);
        assert!(r.text().contains("deformation.npz"), "{}", r.text());
        // The run completes: the same server now computes it.
        std::fs::copy(golden("bunny_targets.npz"), run.join("deformation.npz")).unwrap();
        std::fs::write(run.join("run.json"), "{}").unwrap();
        std::fs::remove_file(run.join("run.lock")).unwrap();
        let r = get(&app, &format!("/{TOKEN}/api/items/0/result?lambda=3")).await;
        assert_eq!(r.status, StatusCode::OK, "{}", r.text());
        let r = get(&app, &format!("/{TOKEN}/api/items")).await;
        let items: serde_json::Value = serde_json::from_slice(&r.body).unwrap();
        assert_eq!(items[0]["status"], "complete");
    });
}

#[test]
fn arguments_that_are_neither_runs_nor_meshes_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let notes = dir.path().join("notes.txt");
    std::fs::write(&notes, "hi").unwrap();
    let e = Viewer::open(&[notes], TOKEN.into()).unwrap_err();
    assert!(format!("{e:#}").contains("notes.txt"), "{e:#}");
    let e = Viewer::open(&[dir.path().join("missing")], TOKEN.into()).unwrap_err();
    assert!(format!("{e:#}").contains("missing"), "{e:#}");
    assert!(Viewer::open(&[], TOKEN.into()).is_err());
}

/// The binary binds 127.0.0.1, prints a URL with a fresh token, and answers over TCP.
#[test]
fn binary_prints_a_loopback_url_with_a_token_and_serves_it() {
    let dir = tempfile::tempdir().unwrap();
    let run = complete_run(dir.path(), "run");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_stylize"))
        .args(["view", "--port", "0"])
        .arg(&run)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let url = loop {
        let line = lines
            .next()
            .expect("the server exited before printing its URL")
            .unwrap();
        if let Some(u) = line.trim().strip_prefix("http://") {
            break u.to_string();
        }
    };
    // Hang up on the banner: a closed stdout must not stop the server.
    drop(lines);
    std::thread::sleep(std::time::Duration::from_millis(300));
    let (authority, path) = url.split_once('/').unwrap();
    assert!(authority.starts_with("127.0.0.1:"), "{url}");
    let token = path.trim_end_matches('/');
    assert_eq!(token.len(), 32, "{url}");
    assert!(token.chars().all(|c| c.is_ascii_hexdigit()));
    assert_ne!(token, TOKEN);
    let http_get = |p: &str| -> String {
        let mut s = std::net::TcpStream::connect(authority).unwrap();
        write!(
            s,
            "GET {p} HTTP/1.1\r\nHost: {authority}\r\nConnection: close\r\n\r\n"
        )
        .unwrap();
        let mut out = String::new();
        s.read_to_string(&mut out).unwrap();
        out
    };
    let ok = http_get(&format!("/{token}/api/items"));
    let bad = http_get("/api/items");
    let traversal = http_get(&format!(
        "/{token}/api/items/0/files/..%2F..%2Fetc%2Fpasswd"
    ));
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(ok.starts_with("HTTP/1.1 200"), "{ok}");
    assert!(ok.contains("\"complete\""), "{ok}");
    assert!(bad.starts_with("HTTP/1.1 403"), "{bad}");
    assert!(traversal.starts_with("HTTP/1.1 400"), "{traversal}");
}

// ---------- replay (snapshots.npz) ----------

/// The golden bunny's rest vertices (side-2 cube frame) and faces.
fn golden_bunny() -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let saved = stylize::saved::SavedDeformation::read(golden("bunny_targets.npz")).unwrap();
    (saved.verts, saved.faces)
}

/// `k` snapshots of `rest`, the k-th scaled by `1 + 0.1·k` (so every snapshot differs).
fn snapshot_positions(rest: &[[f32; 3]], k: usize) -> Vec<f32> {
    (0..k)
        .flat_map(|s| {
            rest.iter()
                .flatten()
                .map(move |&c| c * (1.0 + 0.1 * s as f32))
        })
        .collect()
}

/// Writes a `snapshots.npz` as a run does: `iterations` [K] int64, `x` [K, V, 3] float32 and
/// optionally `faces`.
fn write_snapshots(path: &Path, iterations: &[i64], x: Vec<f32>, faces: Option<&[[u32; 3]]>) {
    use npy::{NpyArray, NpyData};
    let v = x.len() / 3 / iterations.len().max(1);
    let it = NpyArray::new(vec![iterations.len()], NpyData::I64(iterations.to_vec())).unwrap();
    let xa = NpyArray::new(vec![iterations.len(), v, 3], NpyData::F32(x)).unwrap();
    let fa = faces.map(NpyArray::i64_rows3);
    let mut arrays = vec![("iterations", &it), ("x", &xa)];
    if let Some(f) = &fa {
        arrays.push(("faces", f));
    }
    npy::npz::write_npz(path, arrays).unwrap();
}

async fn json(app: &axum::Router, uri: &str) -> serde_json::Value {
    let r = get(app, uri).await;
    assert_eq!(r.status, StatusCode::OK, "{uri}: {}", r.text());
    assert!(
        r.headers["content-type"]
            .to_str()
            .unwrap()
            .starts_with("application/json")
    );
    serde_json::from_slice(&r.body).unwrap()
}

#[test]
fn replay_index_and_snapshots_are_served_as_binary() {
    let dir = tempfile::tempdir().unwrap();
    let run = complete_run(dir.path(), "run");
    let (rest, faces) = golden_bunny();
    let x = snapshot_positions(&rest, 3);
    write_snapshots(&run.join("snapshots.npz"), &[0, 50, 100], x.clone(), None);
    let app = app(&[run]);
    rt().block_on(async {
        let index = json(&app, &format!("/{TOKEN}/api/items/0/replay")).await;
        assert_eq!(index["available"], true, "{index}");
        assert_eq!(index["iterations"], serde_json::json!([0, 50, 100]));
        assert_eq!(index["vertices"], rest.len());
        assert_eq!(index["faces_from"], "deformation.npz");
        for (k, iteration) in [0, 50, 100].into_iter().enumerate() {
            let r = get(&app, &format!("/{TOKEN}/api/items/0/replay/{iteration}")).await;
            assert_eq!(r.status, StatusCode::OK, "{}", r.text());
            assert_eq!(r.headers["content-type"], "application/octet-stream");
            let (head, payload) = unframe(&r.body);
            assert_eq!(head["iteration"], iteration);
            assert_eq!(head["vertices"], rest.len());
            assert_eq!(head["faces"], 0);
            let n = 3 * rest.len();
            assert_eq!(f32s(payload), x[k * n..(k + 1) * n].to_vec());
        }
        // With the faces (the deformation's, whose vertex count matches).
        let r = get(&app, &format!("/{TOKEN}/api/items/0/replay/50?faces=1")).await;
        let (head, payload) = unframe(&r.body);
        assert_eq!(head["faces"], faces.len());
        assert_eq!(payload.len(), 12 * rest.len() + 12 * faces.len());
        let got: Vec<u32> = payload[12 * rest.len()..]
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        assert_eq!(got, faces.iter().flatten().copied().collect::<Vec<_>>());
    });
}

#[test]
fn bad_replay_iterations_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let run = complete_run(dir.path(), "run");
    let (rest, _) = golden_bunny();
    write_snapshots(
        &run.join("snapshots.npz"),
        &[0, 50],
        snapshot_positions(&rest, 2),
        None,
    );
    let app = app(&[run]);
    rt().block_on(async {
        for (it, status) in [
            ("7", StatusCode::NOT_FOUND),
            ("-1", StatusCode::NOT_FOUND),
            ("100", StatusCode::NOT_FOUND),
            ("abc", StatusCode::BAD_REQUEST),
            ("1.5", StatusCode::BAD_REQUEST),
            ("99999999999999999999999", StatusCode::BAD_REQUEST),
        ] {
            let r = get(&app, &format!("/{TOKEN}/api/items/0/replay/{it}")).await;
            assert_eq!(r.status, status, "{it}: {}", r.text());
        }
        let r = get(&app, &format!("/{TOKEN}/api/items/0/replay/7")).await;
        assert!(r.text().contains("iteration 7"), "{}", r.text());
        assert!(r.text().contains("0…50"), "{}", r.text());
        let r = get(&app, &format!("/{TOKEN}/api/items/5/replay")).await;
        assert_eq!(r.status, StatusCode::NOT_FOUND);
    });
}

/// Writes a damaged `snapshots.npz`.
type Damage = Box<dyn Fn()>;

#[test]
fn missing_or_invalid_snapshots_are_no_replay_and_a_live_run_grows() {
    let dir = tempfile::tempdir().unwrap();
    // A run still being written: a lock, no result, no snapshots yet.
    let run = dir.path().join("live");
    std::fs::create_dir_all(&run).unwrap();
    std::fs::write(run.join("task.json"), "{}").unwrap();
    std::fs::write(run.join("run.lock"), "{}").unwrap();
    let (rest, faces) = golden_bunny();
    let path = run.join("snapshots.npz");
    let app = app(std::slice::from_ref(&run));
    rt().block_on(async {
        let uri = format!("/{TOKEN}/api/items/0/replay");
        let index = json(&app, &uri).await;
        assert_eq!(index["available"], false);
        assert_eq!(index["status"], "running");
        assert!(
            index["reason"]
                .as_str()
                .unwrap()
                .contains("no snapshots.npz"),
            "{index}"
        );
        let r = get(&app, &format!("{uri}/0")).await;
        assert_eq!(r.status, StatusCode::CONFLICT, "{}", r.text());

        // Damaged files of every kind: no replay, with the reason; never a 500.
        write_snapshots(&path, &[0, 50], snapshot_positions(&rest, 2), None);
        let whole = std::fs::read(&path).unwrap();
        let mut shape_mismatch = snapshot_positions(&rest, 2);
        shape_mismatch.truncate(3 * rest.len());
        let mut non_finite = snapshot_positions(&rest, 2);
        non_finite[3 * rest.len() + 4] = f32::NAN;
        let cases: Vec<(&str, Damage)> = vec![
            ("half-written", {
                let (p, w) = (path.clone(), whole.clone());
                Box::new(move || std::fs::write(&p, &w[..w.len() / 2]).unwrap())
            }),
            ("empty", {
                let p = path.clone();
                Box::new(move || std::fs::write(&p, b"").unwrap())
            }),
            ("not a zip", {
                let p = path.clone();
                Box::new(move || std::fs::write(&p, b"PK\x03\x04garbage").unwrap())
            }),
            ("K mismatch", {
                // Two iterations but one row of positions.
                let p = path.clone();
                let x = shape_mismatch.clone();
                Box::new(move || {
                    use npy::{NpyArray, NpyData};
                    let it = NpyArray::new(vec![2], NpyData::I64(vec![0, 50])).unwrap();
                    let v = x.len() / 3;
                    let xa = NpyArray::new(vec![1, v, 3], NpyData::F32(x.clone())).unwrap();
                    npy::npz::write_npz(&p, [("iterations", &it), ("x", &xa)]).unwrap();
                })
            }),
            ("not increasing", {
                let p = path.clone();
                let x = snapshot_positions(&rest, 2);
                Box::new(move || write_snapshots(&p, &[50, 50], x.clone(), None))
            }),
            ("non-finite", {
                let p = path.clone();
                let x = non_finite.clone();
                Box::new(move || write_snapshots(&p, &[0, 50], x.clone(), None))
            }),
            ("face out of range", {
                let p = path.clone();
                let x = snapshot_positions(&rest, 2);
                let bad = [[0, 1, rest.len() as u32]];
                Box::new(move || write_snapshots(&p, &[0, 50], x.clone(), Some(&bad[..])))
            }),
        ];
        for (what, damage) in &cases {
            damage();
            let index = json(&app, &uri).await;
            assert_eq!(index["available"], false, "{what}: {index}");
            let reason = index["reason"].as_str().unwrap();
            assert!(reason.contains("snapshots.npz"), "{what}: {reason}");
            let r = get(&app, &format!("{uri}/0")).await;
            assert_eq!(r.status, StatusCode::CONFLICT, "{what}: {}", r.text());
        }

        // The run writes its first two snapshots (with faces), then a third: the index follows.
        write_snapshots(
            &path,
            &[0, 50],
            snapshot_positions(&rest, 2),
            Some(faces.as_slice()),
        );
        let index = json(&app, &uri).await;
        assert_eq!(index["available"], true, "{index}");
        assert_eq!(index["iterations"], serde_json::json!([0, 50]));
        assert_eq!(index["faces_from"], "snapshots.npz");
        let r = get(&app, &format!("{uri}/50?faces=1")).await;
        let (head, _) = unframe(&r.body);
        assert_eq!(head["faces"], faces.len());
        write_snapshots(&path, &[0, 50, 100], snapshot_positions(&rest, 3), None);
        let index = json(&app, &uri).await;
        assert_eq!(index["iterations"], serde_json::json!([0, 50, 100]));
        // No faces anywhere yet (no deformation.npz): the page draws points.
        assert_eq!(index["faces_from"], serde_json::Value::Null);
        let r = get(&app, &format!("{uri}/100?faces=1")).await;
        assert_eq!(r.status, StatusCode::OK, "{}", r.text());
        let (head, payload) = unframe(&r.body);
        assert_eq!(head["faces"], 0);
        assert_eq!(payload.len(), 12 * rest.len());
    });
}

#[test]
fn replay_of_a_mesh_or_through_a_symlink_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let run = complete_run(dir.path(), "run");
    let (rest, _) = golden_bunny();
    let outside = dir.path().join("elsewhere.npz");
    write_snapshots(&outside, &[0], snapshot_positions(&rest, 1), None);
    #[cfg(unix)]
    std::os::unix::fs::symlink(&outside, run.join("snapshots.npz")).unwrap();
    let mesh = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/meshes/bunny.obj");
    let app = app(&[run, mesh]);
    rt().block_on(async {
        #[cfg(unix)]
        {
            let index = json(&app, &format!("/{TOKEN}/api/items/0/replay")).await;
            assert_eq!(index["available"], false, "{index}");
            assert!(
                index["reason"].as_str().unwrap().contains("outside"),
                "{index}"
            );
        }
        let index = json(&app, &format!("/{TOKEN}/api/items/1/replay")).await;
        assert_eq!(index["available"], false);
        assert_eq!(index["status"], "mesh");
        let r = get(&app, &format!("/{TOKEN}/api/items/1/replay/0")).await;
        assert_eq!(r.status, StatusCode::NOT_FOUND);
    });
}

// ---------- metrics, gallery, target normals ----------

#[test]
fn metrics_are_columns_and_garbage_lines_are_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let run = complete_run(dir.path(), "run");
    std::fs::write(
        run.join("metrics.jsonl"),
        "{\"iteration\":1,\"loss\":2.0,\"grad_norm\":0.5,\"seconds\":{\"total\":0.1}}\n\
         \u{0}\u{1} binary garbage\n\
         {\"iteration\":2,\"loss\":1.0,\"stage2_weight\":0.2,\"seconds\":{\"total\":0.2}}\n\
         \"a string\"\n\
         {\"iteration\":3,\"lo",
    )
    .unwrap();
    let empty = dir.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let mesh = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/meshes/bunny.obj");
    let app = app(&[run, empty, mesh]);
    rt().block_on(async {
        let m = json(&app, &format!("/{TOKEN}/api/items/0/metrics")).await;
        assert_eq!(m["available"], true);
        assert_eq!(m["iterations"], serde_json::json!([1.0, 2.0]));
        assert_eq!(m["series"]["loss"], serde_json::json!([2.0, 1.0]));
        assert_eq!(m["series"]["grad_norm"], serde_json::json!([0.5, null]));
        assert_eq!(m["series"]["stage2_weight"], serde_json::json!([null, 0.2]));
        assert_eq!(m["series"]["seconds.total"], serde_json::json!([0.1, 0.2]));
        assert_eq!(m["skipped"], 3);
        assert_eq!(m["first_skipped_line"], 2);
        for id in [1, 2] {
            let m = json(&app, &format!("/{TOKEN}/api/items/{id}/metrics")).await;
            assert_eq!(m["available"], false, "item {id}: {m}");
        }
    });
}

#[test]
fn gallery_of_a_manifest_lists_rows_not_started() {
    let dir = tempfile::tempdir().unwrap();
    let run = complete_run(dir.path(), "runs/bunny-cube");
    std::fs::write(run.join("turntable.png"), b"\x89PNG not really").unwrap();
    let manifest = dir.path().join("batch.toml");
    std::fs::write(
        &manifest,
        "[[run]]\nmesh = \"meshes/bunny.obj\"\nstyle = \"cube\"\nout = \"runs/bunny-cube\"\n\n\
         [[run]]\nmesh = \"meshes/cow.off\"\nprompt = \"a gothic cow\"\nout = \"runs/cow\"\n",
    )
    .unwrap();
    let app = app(std::slice::from_ref(&manifest));
    rt().block_on(async {
        let items = json(&app, &format!("/{TOKEN}/api/items")).await;
        let items = items.as_array().unwrap();
        assert_eq!(items.len(), 2);
        assert_eq!(items[0]["name"], "runs/bunny-cube");
        assert_eq!(items[0]["status"], "complete");
        assert_eq!(items[0]["style"], "cube");
        assert_eq!(items[0]["thumbnail"], "turntable.png");
        assert_eq!(items[0]["row"], 0);
        assert!(
            items[0]["mesh"]
                .as_str()
                .unwrap()
                .ends_with("meshes/bunny.obj")
        );
        assert_eq!(items[1]["name"], "runs/cow");
        assert_eq!(items[1]["status"], "not started");
        assert_eq!(items[1]["prompt"], "a gothic cow");
        assert_eq!(items[1]["thumbnail"], serde_json::Value::Null);
        assert_eq!(items[1]["has_deformation"], false);
        // The row not started answers cleanly.
        let r = get(&app, &format!("/{TOKEN}/api/items/1/files/run.json")).await;
        assert_eq!(r.status, StatusCode::NOT_FOUND, "{}", r.text());
        let r = get(&app, &format!("/{TOKEN}/api/items/1/source")).await;
        assert_eq!(r.status, StatusCode::CONFLICT, "{}", r.text());
        let replay = json(&app, &format!("/{TOKEN}/api/items/1/replay")).await;
        assert_eq!(replay["available"], false);
        let m = json(&app, &format!("/{TOKEN}/api/items/1/metrics")).await;
        assert_eq!(m["available"], false);
        // The row starts: running, with its newest preview as the thumbnail.
        let cow = dir.path().join("runs/cow");
        std::fs::create_dir_all(cow.join("previews")).unwrap();
        std::fs::write(cow.join("task.json"), "{}").unwrap();
        std::fs::write(cow.join("run.lock"), "{}").unwrap();
        for it in ["000050", "000100"] {
            std::fs::write(cow.join(format!("previews/iter_{it}.png")), b"png").unwrap();
        }
        let items = json(&app, &format!("/{TOKEN}/api/items")).await;
        assert_eq!(items[1]["status"], "running");
        assert_eq!(items[1]["thumbnail"], "previews/iter_000100.png");
        let r = get(
            &app,
            &format!("/{TOKEN}/api/items/1/files/previews/iter_000100.png"),
        )
        .await;
        assert_eq!(r.status, StatusCode::OK, "{}", r.text());
    });
    // A manifest that does not parse is refused, naming it.
    let bad = dir.path().join("bad.jsonl");
    std::fs::write(&bad, "{\"mesh\": \"m.obj\"}\n").unwrap();
    let e = Viewer::open(&[bad], TOKEN.into()).unwrap_err();
    assert!(format!("{e:#}").contains("bad.jsonl"), "{e:#}");
}

#[test]
fn target_normals_are_unit_vectors_per_source_vertex() {
    let dir = tempfile::tempdir().unwrap();
    let run = complete_run(dir.path(), "run");
    let running = dir.path().join("running");
    std::fs::create_dir_all(&running).unwrap();
    let mesh = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/meshes/bunny.obj");
    let app = app(&[run, running, mesh]);
    let saved = stylize::saved::SavedDeformation::read(golden("bunny_targets.npz")).unwrap();
    rt().block_on(async {
        let r = get(&app, &format!("/{TOKEN}/api/items/0/targets")).await;
        assert_eq!(r.status, StatusCode::OK, "{}", r.text());
        let (head, payload) = unframe(&r.body);
        assert_eq!(head["vertices"], saved.verts.len());
        let n = f32s(payload);
        assert_eq!(n.len(), 3 * saved.verts.len());
        for (got, raw) in n.chunks_exact(3).zip(&saved.verts_normals) {
            let len = raw.iter().map(|c| c * c).sum::<f32>().sqrt();
            for k in 0..3 {
                assert!((got[k] - raw[k] / len).abs() < 1e-5, "{got:?} vs {raw:?}");
            }
        }
        let r = get(&app, &format!("/{TOKEN}/api/items/1/targets")).await;
        assert_eq!(r.status, StatusCode::CONFLICT, "{}", r.text());
        let r = get(&app, &format!("/{TOKEN}/api/items/2/targets")).await;
        assert_eq!(r.status, StatusCode::NOT_FOUND, "{}", r.text());
    });
}

// ---------- hostile clients (no token needed to connect) ----------

/// `stylize view … RUN` with `extra` options under `sh -c 'ulimit -n FDS'` (when given); returns
/// the child and the `127.0.0.1:PORT/TOKEN/` of its URL.
fn spawn_viewer(run: &Path, fds: Option<u32>, extra: &[&str]) -> (std::process::Child, String) {
    let bin = env!("CARGO_BIN_EXE_stylize");
    let mut cmd = match fds {
        Some(n) => {
            let mut c = std::process::Command::new("sh");
            c.args(["-c", &format!("ulimit -n {n} && exec \"$@\""), "sh", bin]);
            c
        }
        None => std::process::Command::new(bin),
    };
    let mut child = cmd
        .args(["view", "--port", "0"])
        .args(extra)
        .arg(run)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let url = loop {
        let line = lines
            .next()
            .expect("the server exited before printing its URL")
            .unwrap();
        if let Some(u) = line.trim().strip_prefix("http://") {
            break u.to_string();
        }
    };
    (child, url)
}

/// Connects to `authority` within `timeout` (`None` when refused or timed out).
fn connect(authority: &str, timeout: std::time::Duration) -> Option<std::net::TcpStream> {
    let addr: std::net::SocketAddr = authority.parse().unwrap();
    std::net::TcpStream::connect_timeout(&addr, timeout).ok()
}

/// `GET path` on a fresh connection: the status line, or `None` when the server closed the
/// connection without an answer (refused over its cap) or did not answer within 5 s.
fn status_of(authority: &str, path: &str) -> Option<String> {
    use std::time::Duration;
    let mut s = connect(authority, Duration::from_secs(2))?;
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {authority}\r\nConnection: close\r\n\r\n"
    )
    .ok()?;
    let mut out = String::new();
    s.read_to_string(&mut out).ok()?;
    out.lines().next().map(str::to_string)
}

/// Polls `GET path` until it is answered (at most `rounds` tries, 250 ms apart).
fn answered_within(authority: &str, path: &str, rounds: usize) -> Option<String> {
    (0..rounds).find_map(|_| {
        let r = status_of(authority, path);
        if r.is_none() {
            std::thread::sleep(std::time::Duration::from_millis(250));
        }
        r
    })
}

/// About 1,000 idle connections at the usual 1,024-descriptor limit made the server panic
/// ("timers are disabled") on the accept error. Here the limit is 64 descriptors and the cap is
/// set above it, so 200 idle connections make `accept` fail with EMFILE: the server reports it,
/// keeps running, times the idle connections out (1 s here), and then answers the token's
/// request.
#[test]
fn idle_connections_past_the_descriptor_limit_neither_kill_nor_block_the_viewer() {
    use std::time::Duration;
    let dir = tempfile::tempdir().unwrap();
    let run = complete_run(dir.path(), "run");
    let (mut child, url) = spawn_viewer(
        &run,
        Some(64),
        &["--max-connections", "1000", "--header-timeout", "1"],
    );
    let (authority, path) = url.split_once('/').unwrap();
    let token = path.trim_end_matches('/');
    let idle: Vec<_> = (0..200)
        .filter_map(|_| connect(authority, Duration::from_millis(500)))
        .collect();
    assert!(idle.len() > 64, "only {} connections were made", idle.len());
    std::thread::sleep(Duration::from_millis(500));
    assert!(
        child.try_wait().unwrap().is_none(),
        "the viewer died with idle connections open"
    );
    let answer = answered_within(authority, &format!("/{token}/api/items"), 80);
    let alive = child.try_wait().unwrap().is_none();
    drop(idle);
    child.kill().unwrap();
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(alive, "the viewer died: {err}");
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(
        answer.as_deref(),
        Some("HTTP/1.1 200 OK"),
        "the token's request was not answered after the idle connections timed out: {err}"
    );
    assert!(
        err.contains("cannot accept a connection") && err.contains("still serving"),
        "the descriptor exhaustion is reported: {err}"
    );
}

/// Over the connection cap (4 here), connections are closed as soon as they are accepted, so
/// a flood holds no descriptor of the server; a client that sends half a request is closed
/// after the header timeout; and the page's request gets through once the slots free.
#[test]
fn a_flood_of_connections_and_a_slow_client_cost_the_viewer_no_descriptors() {
    use std::time::{Duration, Instant};
    let dir = tempfile::tempdir().unwrap();
    let run = complete_run(dir.path(), "run");
    let (mut child, url) = spawn_viewer(
        &run,
        None,
        &["--max-connections", "4", "--header-timeout", "1"],
    );
    let (authority, path) = url.split_once('/').unwrap();
    let token = path.trim_end_matches('/');
    let fds = || std::fs::read_dir(format!("/proc/{}/fd", child.id())).map(|d| d.count());
    // The baseline once the server has answered (its runtime and the run's files are open).
    assert!(answered_within(authority, &format!("/{token}/api/items"), 40).is_some());
    let before = fds();
    // A slow client: half a request line, then silence.
    let mut slow = connect(authority, Duration::from_secs(2)).unwrap();
    write!(slow, "GET /{token}/api/items HTTP/1.1\r\nHost: x\r\n").unwrap();
    let started = Instant::now();
    let flood: Vec<_> = (0..100)
        .filter_map(|_| connect(authority, Duration::from_millis(500)))
        .collect();
    std::thread::sleep(Duration::from_millis(300));
    let during = fds();
    slow.set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let mut buf = Vec::new();
    let _ = slow.read_to_end(&mut buf);
    let slow_closed_after = started.elapsed();
    let answer = answered_within(authority, &format!("/{token}/api/items"), 80);
    drop(flood);
    child.kill().unwrap();
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    if let (Ok(before), Ok(during)) = (before, during) {
        // The 4 connections the cap lets in, and a little slack for the runtime (100 without a
        // cap).
        assert!(
            during <= before + 4 + 8,
            "{during} descriptors with 100 connections over a cap of 4 (before: {before})"
        );
    }
    assert!(
        slow_closed_after < Duration::from_secs(20),
        "the slow client was never closed"
    );
    assert_eq!(answer.as_deref(), Some("HTTP/1.1 200 OK"), "{err}");
}

/// `?strength=S`: the strength control (`apply --strength`) on the server: S = 1 is the result at
/// λ itself (same positions), S = 3 on the golden bunny stays safe where λ = 3·8 flips (docs/strength.md),
/// the header names the strength, downloads carry it, and bad strengths are a 400.
#[test]
fn strength_pushes_the_result_at_lambda_further() {
    let dir = tempfile::tempdir().unwrap();
    let app = app(&[complete_run(dir.path(), "run")]);
    rt().block_on(async {
        let plain = get(&app, &format!("/{TOKEN}/api/items/0/result?lambda=8")).await;
        let one = get(
            &app,
            &format!("/{TOKEN}/api/items/0/result?lambda=8&strength=1"),
        )
        .await;
        let (head_plain, pos_plain) = unframe(&plain.body);
        let (head_one, pos_one) = unframe(&one.body);
        assert_eq!(pos_plain, pos_one);
        assert!(head_plain["strength"].is_null(), "{head_plain}");
        assert_eq!(head_one["strength"], 1.0, "{head_one}");
        let strong = get(
            &app,
            &format!("/{TOKEN}/api/items/0/result?lambda=8&strength=3"),
        )
        .await;
        assert_eq!(strong.status, 200, "{}", strong.text());
        let (head, pos) = unframe(&strong.body);
        assert_ne!(pos, pos_plain);
        assert_eq!(head["strength"], 3.0, "{head}");
        assert!(head["warnings"].as_array().unwrap().is_empty(), "{head}");
        let big = get(&app, &format!("/{TOKEN}/api/items/0/result?lambda=24")).await;
        assert!(
            !unframe(&big.body).0["warnings"]
                .as_array()
                .unwrap()
                .is_empty()
        );
        let dl = get(
            &app,
            &format!(
                "/{TOKEN}/api/items/0/download?lambda=8&strength=3&format=obj&frame=normalized"
            ),
        )
        .await;
        assert_eq!(dl.status, 200, "{}", dl.text());
        let disposition = dl
            .headers
            .get("content-disposition")
            .unwrap()
            .to_str()
            .unwrap()
            .to_string();
        assert!(
            disposition.contains("_lambda8_strength3.obj"),
            "{disposition}"
        );
        for bad in ["0.5", "0", "-1", "NaN", "inf", "101", "x"] {
            let r = get(
                &app,
                &format!("/{TOKEN}/api/items/0/result?lambda=8&strength={bad}"),
            )
            .await;
            assert_eq!(r.status, 400, "strength={bad}: {}", r.text());
        }
    });
}
