//! The viewer's page and its vendored libraries, embedded in the binary (no network, no build
//! step): `crates/stylize-cli/web/` (three.js and uPlot: `web/vendor/*/README.md` name their
//! versions, licences and tarball hashes).

/// `(path below the token, content type, bytes)` of every static file the page loads.
pub const ASSETS: &[(&str, &str, &[u8])] = &[
    (
        "index.html",
        "text/html; charset=utf-8",
        include_bytes!("../../web/index.html"),
    ),
    (
        "app.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../../web/app.js"),
    ),
    (
        "plots.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../../web/plots.js"),
    ),
    (
        "style.css",
        "text/css; charset=utf-8",
        include_bytes!("../../web/style.css"),
    ),
    (
        "vendor/three/three.module.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../../web/vendor/three/three.module.js"),
    ),
    (
        "vendor/three/three.core.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../../web/vendor/three/three.core.js"),
    ),
    (
        "vendor/three/OrbitControls.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../../web/vendor/three/OrbitControls.js"),
    ),
    (
        "vendor/uplot/uPlot.esm.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../../web/vendor/uplot/uPlot.esm.js"),
    ),
    (
        "vendor/uplot/uPlot.min.css",
        "text/css; charset=utf-8",
        include_bytes!("../../web/vendor/uplot/uPlot.min.css"),
    ),
    (
        "vendor/uplot/LICENSE",
        "text/plain; charset=utf-8",
        include_bytes!("../../web/vendor/uplot/LICENSE"),
    ),
    (
        "vendor/three/LICENSE",
        "text/plain; charset=utf-8",
        include_bytes!("../../web/vendor/three/LICENSE"),
    ),
];

/// The embedded file at `path` (relative to the token), with its content type.
pub fn asset(path: &str) -> Option<(&'static str, &'static [u8])> {
    ASSETS
        .iter()
        .find(|(p, _, _)| *p == path)
        .map(|(_, t, b)| (*t, *b))
}
