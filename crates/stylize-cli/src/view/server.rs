//! The viewer's HTTP routes (axum). Every URL starts with the secret token; anything else is
//! answered `403 Forbidden`. Only `GET` is served.
//!
//! ```text
//! /TOKEN/                                   the page
//! /TOKEN/static/PATH                        the page's scripts, styles and vendored three.js
//! /TOKEN/api/items                          JSON: one ItemInfo per command-line argument
//! /TOKEN/api/items/ID/source                framed: header JSON + f32 positions + u32 faces
//! /TOKEN/api/items/ID/result?lambda=L[&strength=S]
//!                                           framed: header JSON (λ diagnostics) + f32 positions;
//!                                           with S, the result at λ pushed S times as far
//!                                           (`apply --strength`; S in [1, 100])
//! /TOKEN/api/items/ID/max-safe?upper=L     JSON: the strongest safe λ in (0, L] (`lambda`,
//!                                           `first_unsafe`, `safe_again`, `evaluations`;
//!                                           `crate::max_safe`), cached per run and L
//! /TOKEN/api/items/ID/download?lambda=L&format=obj|ply|glb[&frame=input|normalized][&strength=S]
//!                                                          the mesh at λ as a file, in the run's
//!                                                          input frame by default
//! /TOKEN/api/items/ID/files/PATH            a file inside a run directory (images, metrics)
//! /TOKEN/api/items/ID/targets               framed: header JSON + f32 unit target normals, one
//!                                           per source vertex (the saved deformation's)
//! /TOKEN/api/items/ID/metrics               JSON: metrics.jsonl as columns (`available`,
//!                                           `iterations`, `series`, `skipped` lines)
//! /TOKEN/api/items/ID/replay                JSON: the run's snapshot iterations (always 200;
//!                                           `available: false` + `reason` when there is no
//!                                           usable snapshots.npz)
//! /TOKEN/api/items/ID/replay/ITER[?faces=1] framed: header JSON + f32 positions at iteration
//!                                           ITER (+ u32 faces when asked and known)
//! ```
//!
//! **Framed responses** (`application/octet-stream`): a little-endian `u32` header length `H`, `H`
//! bytes of UTF-8 JSON, zero bytes up to the next multiple of 4, then the payload: `3·n`
//! little-endian `f32` positions (side-2 cube frame), and for `source` also `3·m` little-endian
//! `u32` vertex indices. The header holds `vertices`, `faces` and, for results, the λ diagnostics
//! ([`crate::sanity::LambdaSanity`]: `intersections` with the figures, `intersecting_faces` and
//! `new_intersecting_faces` with the face indices, each list cut at
//! [`MAX_LISTED_FACES`] — `intersecting_faces_truncated` says when) and their `warnings`.
//!
//! Status codes: 400 bad λ or path (λ must be finite and in `[0, LAMBDA_MAX]`), 403 missing or
//! wrong token, 404 no such item or file, 405 other methods, 409 a run without its result yet,
//! 500 a file that cannot be read.
//!
//! **Connections** ([`serve_with`], [`Limits`]): any local process can connect, token or not, so
//! the accept loop is built not to be taken down: at most [`Limits::max_connections`] are served at
//! once (more are closed as soon as they are accepted, so they cost no descriptor), a client must
//! send a request's headers within [`Limits::header_timeout`] (idle keep-alive connections and
//! slow senders are closed), a connection is asked to close after
//! [`Limits::connection_lifetime`] (the request in flight is finished, for at most
//! [`Limits::grace`] more), and an accept error (`EMFILE` when descriptors run out, a connection
//! reset before it was accepted) is reported on stderr at most every few seconds and never stops
//! the server.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use axum::Router;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderValue, StatusCode, Uri, header};
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::get;
use mesh_core::io::Format;
use serde::Deserialize;

use super::replay::ReplayState;
use super::{Shape, ViewError, Viewer};

impl IntoResponse for ViewError {
    fn into_response(self) -> Response {
        let status = match &self {
            ViewError::BadRequest(_) => StatusCode::BAD_REQUEST,
            ViewError::NotFound(_) => StatusCode::NOT_FOUND,
            ViewError::NotReady(_) => StatusCode::CONFLICT,
            ViewError::Failed(_) => StatusCode::INTERNAL_SERVER_ERROR,
        };
        (status, no_store(), self.to_string()).into_response()
    }
}

fn no_store() -> [(header::HeaderName, HeaderValue); 1] {
    [(header::CACHE_CONTROL, HeaderValue::from_static("no-store"))]
}

/// The router for `viewer`.
pub fn router(viewer: Arc<Viewer>) -> Router {
    let t = viewer.token.clone();
    let page_url = format!("/{t}/");
    Router::new()
        .route(
            &format!("/{t}"),
            get(move || async move { Redirect::to(&page_url) }),
        )
        .route(&format!("/{t}/"), get(index))
        .route(&format!("/{t}/static/{{*path}}"), get(static_asset))
        .route(&format!("/{t}/api/items"), get(items))
        .route(&format!("/{t}/api/items/{{id}}/source"), get(source))
        .route(&format!("/{t}/api/items/{{id}}/result"), get(result))
        .route(&format!("/{t}/api/items/{{id}}/download"), get(download))
        .route(&format!("/{t}/api/items/{{id}}/max-safe"), get(max_safe))
        .route(&format!("/{t}/api/items/{{id}}/files/{{*path}}"), get(file))
        .route(&format!("/{t}/api/items/{{id}}/metrics"), get(metrics))
        .route(&format!("/{t}/api/items/{{id}}/targets"), get(targets))
        .route(&format!("/{t}/api/items/{{id}}/replay"), get(replay_index))
        .route(
            &format!("/{t}/api/items/{{id}}/replay/{{iteration}}"),
            get(replay_snapshot),
        )
        .fallback(fallback)
        .with_state(viewer)
}

/// 404 inside the token's space, 403 outside it (no hint whether a path exists).
async fn fallback(State(viewer): State<Arc<Viewer>>, uri: Uri) -> Response {
    let prefix = format!("/{}/", viewer.token);
    if uri.path().starts_with(&prefix) {
        (StatusCode::NOT_FOUND, "not found").into_response()
    } else {
        (
            StatusCode::FORBIDDEN,
            "missing or wrong token: open the URL that `stylize view` printed",
        )
            .into_response()
    }
}

async fn index() -> Response {
    static_response("index.html")
}

async fn static_asset(Path(path): Path<String>) -> Response {
    static_response(&path)
}

fn static_response(path: &str) -> Response {
    match super::assets::asset(path) {
        Some((content_type, bytes)) => (
            [(header::CONTENT_TYPE, HeaderValue::from_static(content_type))],
            bytes,
        )
            .into_response(),
        None => (StatusCode::NOT_FOUND, "not found").into_response(),
    }
}

async fn items(State(viewer): State<Arc<Viewer>>) -> Response {
    let v = Arc::clone(&viewer);
    let infos = tokio::task::spawn_blocking(move || {
        v.items
            .iter()
            .enumerate()
            .map(|(i, item)| item.info(i))
            .collect::<Vec<_>>()
    })
    .await;
    match infos {
        Ok(infos) => match serde_json::to_vec(&infos) {
            Ok(json) => (
                no_store(),
                [(
                    header::CONTENT_TYPE,
                    HeaderValue::from_static("application/json"),
                )],
                json,
            )
                .into_response(),
            Err(e) => ViewError::Failed(e.into()).into_response(),
        },
        Err(e) => ViewError::Failed(e.into()).into_response(),
    }
}

/// Runs a blocking computation on an item off the async thread.
async fn on_item<T: Send + 'static>(
    viewer: Arc<Viewer>,
    id: usize,
    f: impl FnOnce(&super::Item) -> Result<T, ViewError> + Send + 'static,
) -> Result<T, ViewError> {
    tokio::task::spawn_blocking(move || f(viewer.item(id)?))
        .await
        .map_err(|e| ViewError::Failed(anyhow::anyhow!("the computation failed: {e}")))?
}

/// A framed response (see the module documentation).
pub fn frame(header_json: &serde_json::Value, payload: &[&[u8]]) -> Vec<u8> {
    let head = header_json.to_string().into_bytes();
    let padded = head.len().div_ceil(4) * 4;
    let mut out = Vec::with_capacity(4 + padded + payload.iter().map(|p| p.len()).sum::<usize>());
    out.extend_from_slice(&(head.len() as u32).to_le_bytes());
    out.extend_from_slice(&head);
    out.resize(4 + padded, 0);
    for p in payload {
        out.extend_from_slice(p);
    }
    out
}

fn f32_bytes(positions: &[[f64; 3]]) -> Vec<u8> {
    positions
        .iter()
        .flatten()
        .flat_map(|&c| (c as f32).to_le_bytes())
        .collect()
}

fn framed(body: Vec<u8>) -> Response {
    (
        no_store(),
        [(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/octet-stream"),
        )],
        body,
    )
        .into_response()
}

async fn source(State(viewer): State<Arc<Viewer>>, Path(id): Path<usize>) -> Response {
    match on_item(viewer, id, |item| item.source()).await {
        Ok(shape) => {
            let head = serde_json::json!({
                "vertices": shape.positions.len(),
                "faces": shape.faces.len(),
            });
            let faces: Vec<u8> = shape
                .faces
                .iter()
                .flatten()
                .flat_map(|v| v.to_le_bytes())
                .collect();
            framed(frame(&head, &[&f32_bytes(&shape.positions), &faces]))
        }
        Err(e) => e.into_response(),
    }
}

/// `?lambda=L` (required) `[&strength=S]`.
#[derive(Debug, Deserialize)]
struct LambdaQuery {
    lambda: f64,
    /// The strength control's `S` (`apply --strength`); absent: the result at λ.
    #[serde(default)]
    strength: Option<f64>,
}

fn result_header(shape: &Shape) -> serde_json::Value {
    let mut head = serde_json::json!({
        "vertices": shape.positions.len(),
        "faces": shape.faces.len(),
    });
    if let Some(s) = &shape.sanity {
        head["lambda"] = s.lambda.into();
        head["strength"] = s.strength.into();
        head["flipped"] = s.flipped.into();
        head["flipped_fraction"] = s.flipped_fraction.into();
        // JSON has no NaN: a source without volume gives null.
        head["volume_ratio"] = if s.volume_ratio.is_finite() {
            s.volume_ratio.into()
        } else {
            serde_json::Value::Null
        };
        head["area_ratio_mean"] = s.area_ratio_mean.into();
        head["area_ratio_std"] = s.area_ratio_std.into();
        head["warnings"] = s.warnings().into();
        head["intersections"] = serde_json::to_value(&s.intersections).unwrap_or_default();
        let listed = |faces: &[u32]| faces[..faces.len().min(MAX_LISTED_FACES)].to_vec();
        head["intersecting_faces"] = listed(&s.intersecting_faces).into();
        head["new_intersecting_faces"] = listed(&s.new_intersecting_faces).into();
        head["intersecting_faces_truncated"] =
            (s.intersecting_faces.len() > MAX_LISTED_FACES).into();
    }
    head
}

/// The most intersecting faces a result header lists (the figures count them all).
pub const MAX_LISTED_FACES: usize = 200_000;

/// `?upper=L` (required).
#[derive(Debug, Deserialize)]
struct UpperQuery {
    upper: f64,
}

async fn max_safe(
    State(viewer): State<Arc<Viewer>>,
    Path(id): Path<usize>,
    Query(q): Query<UpperQuery>,
) -> Response {
    match on_item(viewer, id, move |item| item.max_safe(q.upper)).await {
        Ok(found) => json_response(&serde_json::json!({
            "upper": q.upper,
            "lambda": found.lambda,
            "first_unsafe": found.first_unsafe,
            "safe_again": found.safe_again,
            "evaluations": found.evaluations,
        })),
        Err(e) => e.into_response(),
    }
}

async fn result(
    State(viewer): State<Arc<Viewer>>,
    Path(id): Path<usize>,
    Query(q): Query<LambdaQuery>,
) -> Response {
    match on_item(viewer, id, move |item| item.at(q.lambda, q.strength)).await {
        Ok(shape) => framed(frame(
            &result_header(&shape),
            &[&f32_bytes(&shape.positions)],
        )),
        Err(e) => e.into_response(),
    }
}

/// `?lambda=L&format=obj|ply|glb[&strength=S]`.
#[derive(Debug, Deserialize)]
struct DownloadQuery {
    lambda: f64,
    #[serde(default)]
    strength: Option<f64>,
    format: String,
    /// `input` (the default when the run records its input frame) or `normalized`.
    #[serde(default)]
    frame: Option<String>,
}

async fn download(
    State(viewer): State<Arc<Viewer>>,
    Path(id): Path<usize>,
    Query(q): Query<DownloadQuery>,
) -> Response {
    let Some(format) =
        Format::from_extension(&q.format).filter(|f| Format::WITH_NORMALS.contains(f))
    else {
        return ViewError::BadRequest(format!(
            "format must be {}, got {:?}",
            Format::list(&Format::WITH_NORMALS, "", " or "),
            q.format
        ))
        .into_response();
    };
    let frame = match q
        .frame
        .as_deref()
        .map(str::parse::<stylize::frame::OutputFrame>)
    {
        None => None,
        Some(Ok(f)) => Some(f),
        Some(Err(e)) => return ViewError::BadRequest(e.to_string()).into_response(),
    };
    let format = format.extension();
    let fmt = format;
    let made = on_item(viewer, id, move |item| {
        let shape = item.in_frame(item.at(q.lambda, q.strength)?, frame)?;
        let mesh = mesh_core::TriMesh::new(shape.positions, shape.faces);
        let normals =
            mesh_core::normals::vertex_normals_area_weighted(&mesh.positions, &mesh.faces);
        let dir = tempfile::tempdir().map_err(|e| ViewError::Failed(e.into()))?;
        let path = dir.path().join(format!("mesh.{fmt}"));
        mesh_core::io::write_mesh(&path, &mesh, Some(&normals))
            .map_err(|e| ViewError::Failed(e.into()))?;
        let bytes = std::fs::read(&path).map_err(|e| ViewError::Failed(e.into()))?;
        let strength = q
            .strength
            .map(|s| format!("_strength{s}"))
            .unwrap_or_default();
        Ok((
            format!("{}_lambda{}{strength}.{fmt}", item.stem(), q.lambda),
            bytes,
        ))
    })
    .await;
    match made {
        Ok((name, bytes)) => {
            let disposition = HeaderValue::from_str(&format!("attachment; filename=\"{name}\""))
                .unwrap_or_else(|_| HeaderValue::from_static("attachment"));
            (
                no_store(),
                [
                    (
                        header::CONTENT_TYPE,
                        HeaderValue::from_static(content_type(format)),
                    ),
                    (header::CONTENT_DISPOSITION, disposition),
                ],
                bytes,
            )
                .into_response()
        }
        Err(e) => e.into_response(),
    }
}

fn content_type(ext: &str) -> &'static str {
    match ext {
        "png" => "image/png",
        "gif" => "image/gif",
        "json" => "application/json",
        "jsonl" | "toml" | "txt" | "obj" | "off" => "text/plain; charset=utf-8",
        _ => "application/octet-stream",
    }
}

async fn file(
    State(viewer): State<Arc<Viewer>>,
    Path((id, path)): Path<(usize, String)>,
) -> Response {
    let read = on_item(viewer, id, move |item| match item {
        super::Item::Run(run) => {
            let resolved = run.resolve_file(&path)?;
            let bytes = std::fs::read(&resolved).map_err(|e| {
                ViewError::Failed(
                    anyhow::Error::from(e).context(format!("cannot read {}", resolved.display())),
                )
            })?;
            let ext = resolved
                .extension()
                .and_then(|e| e.to_str())
                .map(str::to_ascii_lowercase)
                .unwrap_or_default();
            Ok((content_type(&ext), bytes))
        }
        super::Item::Mesh(m) => Err(ViewError::NotFound(format!(
            "{} is a mesh, not a run directory: it has no files",
            m.name
        ))),
    })
    .await;
    match read {
        Ok((content_type, bytes)) => (
            no_store(),
            [(header::CONTENT_TYPE, HeaderValue::from_static(content_type))],
            bytes,
        )
            .into_response(),
        Err(e) => e.into_response(),
    }
}

/// How many clients the server keeps, and for how long (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Connections served at once; more are closed as soon as they are accepted.
    pub max_connections: usize,
    /// Time a client has to send a request's headers (also how long an idle keep-alive
    /// connection is kept).
    pub header_timeout: Duration,
    /// Age after which a connection is asked to close (after its request in flight).
    pub connection_lifetime: Duration,
    /// Time a connection asked to close has to finish its response.
    pub grace: Duration,
}

impl Default for Limits {
    /// 64 connections (a page makes a handful), 10 s for headers, 60 s per connection, 10 s grace.
    fn default() -> Self {
        Self {
            max_connections: 64,
            header_timeout: Duration::from_secs(10),
            connection_lifetime: Duration::from_secs(60),
            grace: Duration::from_secs(10),
        }
    }
}

/// The wait after an accept error before the next accept (lets a full descriptor table drain).
const ACCEPT_BACKOFF: Duration = Duration::from_millis(50);

/// The least time between two accept-error reports on stderr.
const ACCEPT_REPORT_INTERVAL: Duration = Duration::from_secs(10);

/// Serves with the default [`Limits`] until the process ends.
pub async fn serve(listener: tokio::net::TcpListener, viewer: Arc<Viewer>) -> std::io::Result<()> {
    serve_with(listener, viewer, Limits::default()).await
}

/// Decrements the open-connection count when a connection's task ends.
struct Open(Arc<AtomicUsize>);

impl Drop for Open {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

/// Serves `viewer` on `listener` with `limits` until the process ends (never returns an error:
/// accept errors are reported and waited out).
pub async fn serve_with(
    listener: tokio::net::TcpListener,
    viewer: Arc<Viewer>,
    limits: Limits,
) -> std::io::Result<()> {
    use hyper_util::rt::{TokioIo, TokioTimer};
    use hyper_util::service::TowerToHyperService;

    let app = router(viewer);
    let open = Arc::new(AtomicUsize::new(0));
    let mut last_report: Option<Instant> = None;
    let mut unreported = 0u64;
    loop {
        let stream = match listener.accept().await {
            Ok((stream, _)) => stream,
            Err(e) => {
                unreported += 1;
                if last_report.is_none_or(|t| t.elapsed() >= ACCEPT_REPORT_INTERVAL) {
                    errln!(
                        "stylize view: cannot accept a connection ({e}; {unreported} such error(s) \
                         since the last report); still serving"
                    );
                    last_report = Some(Instant::now());
                    unreported = 0;
                }
                tokio::time::sleep(ACCEPT_BACKOFF).await;
                continue;
            }
        };
        if open.load(Ordering::SeqCst) >= limits.max_connections {
            // Closed at once: a flood of idle connections costs no descriptor.
            drop(stream);
            continue;
        }
        open.fetch_add(1, Ordering::SeqCst);
        let guard = Open(Arc::clone(&open));
        let service = TowerToHyperService::new(app.clone());
        tokio::spawn(async move {
            let _guard = guard;
            let mut conn = std::pin::pin!(
                hyper::server::conn::http1::Builder::new()
                    .timer(TokioTimer::new())
                    .header_read_timeout(limits.header_timeout)
                    .serve_connection(TokioIo::new(stream), service)
            );
            tokio::select! {
                _ = conn.as_mut() => {}
                () = tokio::time::sleep(limits.connection_lifetime) => {
                    conn.as_mut().graceful_shutdown();
                    let _ = tokio::time::timeout(limits.grace, conn).await;
                }
            }
        });
    }
}

fn json_response(value: &serde_json::Value) -> Response {
    (
        no_store(),
        [(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/json"),
        )],
        value.to_string(),
    )
        .into_response()
}

/// The replay index: which iterations `snapshots.npz` holds right now.
async fn replay_index(State(viewer): State<Arc<Viewer>>, Path(id): Path<usize>) -> Response {
    let index = on_item(viewer, id, |item| {
        Ok(match item {
            super::Item::Run(run) => match run.replay() {
                ReplayState::Available(s) => {
                    let faces = run.replay_faces(&s).map(|(_, from)| from);
                    serde_json::json!({
                        "available": true,
                        "status": run.status(),
                        "iterations": s.iterations,
                        "vertices": s.vertices,
                        "faces_from": faces,
                    })
                }
                ReplayState::Unavailable(reason) => serde_json::json!({
                    "available": false,
                    "status": run.status(),
                    "iterations": [],
                    "reason": reason,
                }),
            },
            super::Item::Mesh(m) => serde_json::json!({
                "available": false,
                "status": "mesh",
                "iterations": [],
                "reason": format!("{} is a mesh, not a run: it has no replay", m.name),
            }),
        })
    })
    .await;
    match index {
        Ok(v) => json_response(&v),
        Err(e) => e.into_response(),
    }
}

/// `?faces=1`: also send the faces.
#[derive(Debug, Deserialize)]
struct ReplayQuery {
    #[serde(default)]
    faces: Option<u8>,
}

/// The positions of one snapshot.
async fn replay_snapshot(
    State(viewer): State<Arc<Viewer>>,
    Path((id, iteration)): Path<(usize, i64)>,
    Query(q): Query<ReplayQuery>,
) -> Response {
    let want_faces = q.faces.unwrap_or(0) != 0;
    let made = on_item(viewer, id, move |item| {
        let run = match item {
            super::Item::Run(run) => run,
            super::Item::Mesh(m) => {
                return Err(ViewError::NotFound(format!(
                    "{} is a mesh, not a run: it has no replay",
                    m.name
                )));
            }
        };
        let snapshots = match run.replay() {
            ReplayState::Available(s) => s,
            ReplayState::Unavailable(reason) => return Err(ViewError::NotReady(reason)),
        };
        let Some(x) = snapshots.at(iteration) else {
            let (first, last) = (
                snapshots.iterations.first().copied().unwrap_or(0),
                snapshots.iterations.last().copied().unwrap_or(0),
            );
            return Err(ViewError::NotFound(format!(
                "run {} has no snapshot at iteration {iteration} ({} snapshots, iterations {first}…{last})",
                run.name,
                snapshots.iterations.len()
            )));
        };
        let positions: Vec<u8> = x.iter().flat_map(|c| c.to_le_bytes()).collect();
        let faces = if want_faces {
            run.replay_faces(&snapshots).map(|(f, _)| f)
        } else {
            None
        };
        let head = serde_json::json!({
            "iteration": iteration,
            "vertices": snapshots.vertices,
            "faces": faces.as_ref().map_or(0, Vec::len),
        });
        let face_bytes: Vec<u8> = faces
            .iter()
            .flatten()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        Ok(frame(&head, &[&positions, &face_bytes]))
    })
    .await;
    match made {
        Ok(body) => framed(body),
        Err(e) => e.into_response(),
    }
}

/// The run's metrics as columns (always 200 for a run; `available: false` without the file).
async fn metrics(State(viewer): State<Arc<Viewer>>, Path(id): Path<usize>) -> Response {
    let table = on_item(viewer, id, |item| match item {
        super::Item::Run(run) => run.metrics(),
        super::Item::Mesh(_) => Ok(None),
    })
    .await;
    match table {
        Ok(Some(t)) => match serde_json::to_value(&t) {
            Ok(mut v) => {
                v["available"] = true.into();
                json_response(&v)
            }
            Err(e) => ViewError::Failed(e.into()).into_response(),
        },
        Ok(None) => json_response(&serde_json::json!({
            "available": false,
            "iterations": [],
            "series": {},
            "skipped": 0,
        })),
        Err(e) => e.into_response(),
    }
}

/// The saved deformation's target normals (unit length), in the source's vertex order.
async fn targets(State(viewer): State<Arc<Viewer>>, Path(id): Path<usize>) -> Response {
    match on_item(viewer, id, |item| item.target_normals()).await {
        Ok(normals) => framed(frame(
            &serde_json::json!({ "vertices": normals.len() }),
            &[&f32_bytes(&normals)],
        )),
        Err(e) => e.into_response(),
    }
}

/// A connection whose bytes are in memory: reads give `input` then end of file, writes go to
/// `output` (for [`answer_raw`]).
struct MemoryIo {
    input: Vec<u8>,
    at: usize,
    output: Arc<std::sync::Mutex<Vec<u8>>>,
}

impl hyper::rt::Read for MemoryIo {
    fn poll_read(
        self: std::pin::Pin<&mut Self>,
        _cx: &mut std::task::Context<'_>,
        mut buf: hyper::rt::ReadBufCursor<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        let this = self.get_mut();
        let n = (this.input.len() - this.at).min(buf.remaining());
        buf.put_slice(&this.input[this.at..this.at + n]);
        this.at += n;
        std::task::Poll::Ready(Ok(()))
    }
}

impl hyper::rt::Write for MemoryIo {
    fn poll_write(
        self: std::pin::Pin<&mut Self>,
        _cx: &mut std::task::Context<'_>,
        data: &[u8],
    ) -> std::task::Poll<std::io::Result<usize>> {
        self.output
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .extend_from_slice(data);
        std::task::Poll::Ready(Ok(data.len()))
    }

    fn poll_flush(
        self: std::pin::Pin<&mut Self>,
        _cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::task::Poll::Ready(Ok(()))
    }

    fn poll_shutdown(
        self: std::pin::Pin<&mut Self>,
        _cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::task::Poll::Ready(Ok(()))
    }
}

/// The bytes the server writes back on a connection that sends `request` (raw HTTP/1, one or
/// several pipelined requests) and then ends: hyper's parser, the router and the handlers as
/// [`serve_with`] runs them, without a socket (`cargo xtask fuzz --target view-http`). At most
/// 10 s per call.
pub fn answer_raw(viewer: Arc<Viewer>, request: Vec<u8>) -> std::io::Result<Vec<u8>> {
    use hyper_util::rt::TokioTimer;
    use hyper_util::service::TowerToHyperService;

    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .max_blocking_threads(2)
        .build()?;
    let output = Arc::new(std::sync::Mutex::new(Vec::new()));
    let io = MemoryIo {
        input: request,
        at: 0,
        output: Arc::clone(&output),
    };
    runtime.block_on(async move {
        let conn = hyper::server::conn::http1::Builder::new()
            .timer(TokioTimer::new())
            .header_read_timeout(Limits::default().header_timeout)
            .serve_connection(io, TowerToHyperService::new(router(viewer)));
        let _ = tokio::time::timeout(Duration::from_secs(10), conn).await;
    });
    let bytes = output
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .clone();
    Ok(bytes)
}
