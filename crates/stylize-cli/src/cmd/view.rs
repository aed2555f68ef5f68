//! `stylize view`: serve a local web page showing runs and meshes (see [`crate::view`]).
//!
//! Binds `127.0.0.1` by default (another `--host` is the user's choice and is warned about), prints
//! the page's URL — which carries a fresh random token every request must present — and serves
//! until Ctrl-C. Without `--port`, the first free port of 8765–8774 is used (then any free port).

use std::net::IpAddr;
#[cfg(feature = "view")]
use std::net::{SocketAddr, TcpListener};
use std::path::PathBuf;

#[cfg(feature = "view")]
use anyhow::Context;

/// Arguments of `stylize view`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run directories, mesh files and/or batch manifests (one run per row, started or not) to
    /// show; several runs open on a gallery.
    #[arg(required = true, value_name = "RUN_DIR|MESH|MANIFEST")]
    pub paths: Vec<PathBuf>,
    /// Port (default: the first free one of 8765–8774; 0: any free port).
    #[arg(long)]
    pub port: Option<u16>,
    /// Address to bind. Anything but a loopback address exposes the runs to whoever can reach it
    /// and has the URL.
    #[arg(long, default_value = "127.0.0.1")]
    pub host: IpAddr,
    /// Open the page in the default browser (`xdg-open`).
    #[arg(long)]
    pub open: bool,
    /// Connections served at once (more are closed on accept).
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u16).range(1..=1024), hide = true)]
    pub max_connections: u16,
    /// Seconds a client has to send a request's headers (idle connections are closed after it).
    #[arg(long, default_value_t = 10.0, value_parser = positive_seconds, hide = true)]
    pub header_timeout: f64,
}

/// A number of seconds in (0, 3600].
fn positive_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if v.is_finite() && v > 0.0 && v <= 3600.0 {
        Ok(v)
    } else {
        Err(format!("must be a number of seconds in (0, 3600], got {s}"))
    }
}

/// The first default port tried.
pub const DEFAULT_PORT: u16 = 8765;

#[cfg(feature = "view")]
fn bind(host: IpAddr, port: Option<u16>) -> anyhow::Result<TcpListener> {
    match port {
        Some(p) => TcpListener::bind(SocketAddr::new(host, p))
            .with_context(|| format!("cannot listen on {host} port {p} (try another --port, or --port 0 for any free one)")),
        None => {
            for p in DEFAULT_PORT..DEFAULT_PORT + 10 {
                if let Ok(l) = TcpListener::bind(SocketAddr::new(host, p)) {
                    return Ok(l);
                }
            }
            TcpListener::bind(SocketAddr::new(host, 0))
                .with_context(|| format!("cannot listen on {host}"))
        }
    }
}

/// Runs `stylize view`.
#[cfg(feature = "view")]
pub fn run(args: Args) -> anyhow::Result<()> {
    use std::io::Write;
    use std::sync::Arc;

    use crate::view::{Viewer, random_token};

    let viewer = Arc::new(Viewer::open(&args.paths, random_token())?);
    let limits = crate::view::server::Limits {
        max_connections: usize::from(args.max_connections),
        header_timeout: std::time::Duration::from_secs_f64(args.header_timeout),
        ..crate::view::server::Limits::default()
    };
    let listener = bind(args.host, args.port)?;
    let addr = listener
        .local_addr()
        .context("cannot read the bound address")?;
    listener
        .set_nonblocking(true)
        .context("cannot configure the listening socket")?;
    let url = match addr {
        SocketAddr::V6(a) => format!("http://[{}]:{}/{}/", a.ip(), a.port(), viewer.token),
        SocketAddr::V4(a) => format!("http://{}:{}/{}/", a.ip(), a.port(), viewer.token),
    };
    if !addr.ip().is_loopback() {
        errln!(
            "warning: listening on {} — anyone who can reach this address and knows the URL can see these runs",
            addr.ip()
        );
    }
    // The banner goes to stdout; a closed or broken stdout (`stylize view … | head -2`, a test that
    // reads the URL and hangs up) must not stop the server, so write errors only move the URL to
    // stderr.
    let mut banner = format!("stylize view: {} item(s) at\n  {url}\n", viewer.items.len());
    if addr.ip().is_loopback() {
        banner.push_str(&format!(
            "from another machine: ssh -L {p}:127.0.0.1:{p} THIS_HOST, then open the same URL\n",
            p = addr.port()
        ));
    }
    banner.push_str("Ctrl-C to stop\n");
    let mut out = std::io::stdout().lock();
    if out
        .write_all(banner.as_bytes())
        .and_then(|()| out.flush())
        .is_err()
    {
        errln!("stylize view: serving at {url}");
    }
    drop(out);
    if args.open
        && let Err(e) = std::process::Command::new("xdg-open").arg(&url).spawn()
    {
        errln!("warning: cannot open a browser (xdg-open: {e}); open the URL above yourself");
    }
    // Timers: the accept loop's back-off and the connections' timeouts. The blocking pool (mesh
    // loading, dARAP solves) is bounded; at most `max_connections` requests wait for it.
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_io()
        .enable_time()
        .max_blocking_threads(8)
        .build()
        .context("cannot start the server's runtime")?;
    runtime.block_on(async move {
        let listener = tokio::net::TcpListener::from_std(listener)
            .context("cannot register the listening socket")?;
        crate::view::server::serve_with(listener, viewer, limits)
            .await
            .context("the server stopped")
    })
}
