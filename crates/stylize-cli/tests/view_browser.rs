//! `stylize view` in a real browser: headless Chromium (Debian's `chromium`, installed by
//! `scripts/setup.sh`; WebGL on the CPU through SwiftShader) loads the page served by the binary,
//! sets λ to two values through the page's own slider handler (`?lambda=L`), and takes a
//! screenshot of each. Asserted: the page reports no error and shows the requested λ; the mesh is
//! visible in both halves (before | after); the "before" half is the same in both screenshots (the
//! camera does not depend on λ) while the "after" half differs.
//!
//! Without Chromium the test is skipped with a loud message (set `CHROMIUM` to its path if it is
//! installed elsewhere). `STYLIZE_VIEW_SCREENSHOTS=DIR` keeps the screenshots in DIR.

#![allow(clippy::unwrap_used)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

const BACKGROUND: [u8; 3] = [0xf4, 0xf5, 0xf7];
const WIDTH: u32 = 1280;
const HEIGHT: u32 = 720;

fn chromium() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    ["chromium", "chromium-browser", "google-chrome"]
        .iter()
        .find_map(|name| {
            std::env::var_os("PATH").and_then(|paths| {
                std::env::split_paths(&paths)
                    .map(|d| d.join(name))
                    .find(|p| p.is_file())
            })
        })
}

struct Server(Child);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `stylize view --port 0 RUN` and returns it with its printed URL.
fn serve(run: &Path) -> (Server, String) {
    serve_all(&[run])
}

/// Starts `stylize view --port 0 PATHS…` and returns it with its printed URL.
fn serve_all(paths: &[&Path]) -> (Server, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_stylize"))
        .args(["view", "--port", "0"])
        .args(paths)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let url = loop {
        let line = lines
            .next()
            .expect("the server exited before printing its URL")
            .unwrap();
        let line = line.trim();
        if line.starts_with("http://") {
            break line.to_string();
        }
    };
    // Keep reading the server's stdout (dropping the pipe would close it under the server).
    std::thread::spawn(move || lines.for_each(drop));
    (Server(child), url)
}

struct Shot {
    rgb: Vec<u8>,
    width: usize,
    height: usize,
    dom: String,
    console: Vec<String>,
}

/// Runs Chromium once on `url` (a fresh profile) and reads its screenshot and DOM. (Chromium used
/// to fail here about one run in three with `ERR_CONNECTION_REFUSED`: the test dropped the
/// server's stdout and the server exited on the broken pipe. The server now ignores a closed
/// stdout and `serve` keeps draining it.)
fn screenshot(chromium: &Path, url: &str, out: &Path, profile: &Path) -> Shot {
    let _ = std::fs::remove_dir_all(profile);
    screenshot_once(chromium, url, out, profile).unwrap_or_else(|e| panic!("{e}"))
}

fn screenshot_once(chromium: &Path, url: &str, out: &Path, profile: &Path) -> Result<Shot, String> {
    let output = Command::new(chromium)
        .args([
            "--headless=new",
            "--no-sandbox",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--hide-scrollbars",
            "--enable-logging=stderr",
            "--v=0",
            "--virtual-time-budget=60000",
            "--dump-dom",
        ])
        .arg(format!("--window-size={WIDTH},{HEIGHT}"))
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("--screenshot={}", out.display()))
        .arg(url)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    if !(output.status.success() && out.is_file()) {
        return Err(format!("chromium failed ({}): {stderr}", output.status));
    }
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(out).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    assert!(channels >= 3, "{:?}", info.color_type);
    let rgb = buf[..info.buffer_size()]
        .chunks_exact(channels)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    Ok(Shot {
        rgb,
        width: info.width as usize,
        height: info.height as usize,
        dom: String::from_utf8_lossy(&output.stdout).into_owned(),
        console: stderr
            .lines()
            .filter(|l| l.contains("CONSOLE"))
            .map(str::to_string)
            .collect(),
    })
}

impl Shot {
    fn pixel(&self, x: usize, y: usize) -> [u8; 3] {
        let i = 3 * (y * self.width + x);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    /// Pixels of the canvas band (rows 15%–85%: below the header, above the footer) in the
    /// columns `x0..x1`.
    fn band(&self, x0: usize, x1: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
        let (y0, y1) = (self.height * 15 / 100, self.height * 85 / 100);
        (y0..y1).flat_map(move |y| (x0..x1).map(move |x| (x, y)))
    }

    /// Fraction of the band's pixels in `x0..x1` that are not background.
    fn coverage(&self, x0: usize, x1: usize) -> f64 {
        let far = |p: [u8; 3]| p.iter().zip(BACKGROUND).any(|(a, b)| a.abs_diff(b) > 24);
        let (mut hit, mut all) = (0usize, 0usize);
        for (x, y) in self.band(x0, x1) {
            all += 1;
            hit += usize::from(far(self.pixel(x, y)));
        }
        hit as f64 / all as f64
    }

    /// Fraction of the band's pixels in `x0..x1` that differ between two shots.
    fn difference(&self, other: &Shot, x0: usize, x1: usize) -> f64 {
        let (mut diff, mut all) = (0usize, 0usize);
        for (x, y) in self.band(x0, x1) {
            all += 1;
            let (a, b) = (self.pixel(x, y), other.pixel(x, y));
            diff += usize::from(a.iter().zip(b).any(|(p, q)| p.abs_diff(q) > 24));
        }
        diff as f64 / all as f64
    }
}

fn no_chromium() {
    eprintln!();
    eprintln!("############################################################################");
    eprintln!("SKIPPED view_browser: no chromium on PATH (install it: bash scripts/setup.sh,");
    eprintln!("or `apt-get install chromium`; or set CHROMIUM=/path/to/chrome)");
    eprintln!("############################################################################");
}

/// The `<html …>` tag of a dumped DOM (the page reports through its attributes).
fn html_tag(dom: &str) -> &str {
    dom.find("<html")
        .and_then(|i| dom[i..].find('>').map(|j| &dom[i..i + j]))
        .unwrap_or_default()
}

/// The value of attribute `name` in the `<html>` tag.
fn html_attr(dom: &str, name: &str) -> Option<String> {
    let tag = html_tag(dom);
    let key = format!("{name}=\"");
    let i = tag.find(&key)? + key.len();
    Some(tag[i..].split('"').next()?.to_string())
}

/// Where screenshots go: `STYLIZE_VIEW_SCREENSHOTS` when set, else `fallback`.
fn shot_path(fallback: &Path, name: &str) -> PathBuf {
    match std::env::var_os("STYLIZE_VIEW_SCREENSHOTS").map(PathBuf::from) {
        Some(d) => {
            std::fs::create_dir_all(&d).unwrap();
            d.join(name)
        }
        None => fallback.join(name),
    }
}

/// Screenshot of `url` that must have finished without page errors or console output.
fn clean_shot(chromium: &Path, url: &str, out: &Path, profile: &Path) -> Shot {
    let shot = screenshot(chromium, url, out, profile);
    assert_eq!(
        html_attr(&shot.dom, "data-state").as_deref(),
        Some("ready"),
        "{url}: the page did not finish: {}",
        &shot.dom[..shot.dom.len().min(800)]
    );
    assert!(
        html_attr(&shot.dom, "data-errors").is_none(),
        "{url}: page errors: {}",
        shot.dom
    );
    assert!(
        shot.console.is_empty(),
        "{url}: console output: {:?}",
        shot.console
    );
    shot
}

fn golden_npz() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/golden/bunny_targets.npz")
}

/// A complete run of the golden bunny (λ = 8), with `snapshots.npz` at iterations 0, 50, 100 —
/// snapshot k is the rest mesh stretched along x by 1 + 0.35·k, so the shape visibly changes —
/// and a `metrics.jsonl` of 100 iterations with two garbage lines and a partial last line.
fn replay_run(parent: &Path) -> PathBuf {
    use npy::{NpyArray, NpyData};
    let run = parent.join("replay_run");
    std::fs::create_dir_all(&run).unwrap();
    std::fs::copy(golden_npz(), run.join("deformation.npz")).unwrap();
    std::fs::write(run.join("run.json"), r#"{"lambda": 8.0, "objective": "normal alignment with style cube", "vertices": 1839, "faces": 3674, "seconds": {"setup": 0.1, "loop": 2.5}, "task": {"style": "cube"}}"#).unwrap();
    std::fs::write(run.join("config.toml"), "[darap]\nlambda = 8.0\n").unwrap();
    let saved = stylize::saved::SavedDeformation::read(golden_npz()).unwrap();
    let iterations = [0i64, 50, 100];
    let x: Vec<f32> = (0..iterations.len())
        .flat_map(|k| {
            saved
                .verts
                .iter()
                .flat_map(move |p| [p[0] * (1.0 + 0.35 * k as f32), p[1], p[2]])
        })
        .collect();
    let it = NpyArray::new(vec![3], NpyData::I64(iterations.to_vec())).unwrap();
    let xa = NpyArray::new(vec![3, saved.verts.len(), 3], NpyData::F32(x)).unwrap();
    npy::npz::write_npz(run.join("snapshots.npz"), [("iterations", &it), ("x", &xa)]).unwrap();
    let mut metrics = String::new();
    for i in 1..=100 {
        let t = f64::from(i);
        metrics.push_str(&format!(
            "{{\"iteration\":{i},\"loss\":{},\"loss_stage1\":{},\"loss_stage2\":{},\"stage2_weight\":{},\"grad_norm\":{},\"seconds\":{{\"render\":0.01,\"guidance\":{},\"total\":0.05}}}}\n",
            2.0 / t.sqrt(),
            1.5 / t.sqrt(),
            0.5 / t.sqrt(),
            (t / 100.0).min(1.0),
            1.0 / t,
            0.03 + 0.001 * (t % 7.0),
        ));
        if i == 30 {
            metrics.push_str("garbage that is not JSON\n[1, 2, 3]\n");
        }
    }
    metrics.push_str("{\"iteration\":101,\"lo");
    std::fs::write(run.join("metrics.jsonl"), metrics).unwrap();
    run
}

#[test]
fn replay_scrubber_changes_the_shape_and_plots_render() {
    let Some(chromium) = chromium() else {
        no_chromium();
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let run = replay_run(dir.path());
    let (_server, url) = serve(&run);
    let shots: Vec<Shot> = ["0", "100"]
        .iter()
        .map(|it| {
            let shot = clean_shot(
                &chromium,
                &format!("{url}?panel=1&iteration={it}"),
                &shot_path(dir.path(), &format!("view_replay_iter{it}.png")),
                &dir.path().join(format!("profile{it}")),
            );
            assert_eq!(html_attr(&shot.dom, "data-replay").as_deref(), Some(*it));
            // loss terms, stage-II weight, gradient norm, seconds: four charts, drawn by uPlot.
            assert_eq!(html_attr(&shot.dom, "data-plots").as_deref(), Some("4"));
            assert!(
                shot.dom.contains("class=\"uplot"),
                "no uPlot chart in the page"
            );
            assert!(
                shot.dom.contains("3 malformed line(s) skipped"),
                "the skipped lines are not reported"
            );
            assert!(shot.dom.contains("normal alignment with style cube"));
            assert!(shot.dom.contains("iteration 100 / 100") || *it != "100");
            shot
        })
        .collect();
    // The canvas is left of the 420-px panel: before | after halves of what remains.
    let canvas = WIDTH as usize - 420;
    let half = canvas / 2;
    for shot in &shots {
        assert!(shot.coverage(0, half) > 0.03 && shot.coverage(half, canvas) > 0.03);
        // The plots draw lines and labels in the panel.
        let panel = shot.coverage(canvas + 10, WIDTH as usize - 10);
        assert!(panel > 0.01, "the panel looks empty ({panel:.4})");
    }
    let before = shots[0].difference(&shots[1], 0, half);
    let after = shots[0].difference(&shots[1], half, canvas);
    assert!(
        before < 0.002,
        "the 'before' view changed with the replay ({before:.4})"
    );
    assert!(
        after > 0.02,
        "the 'after' view did not change between iterations 0 and 100 ({after:.4})"
    );
}

#[test]
fn target_normals_and_the_reference_look() {
    let Some(chromium) = chromium() else {
        no_chromium();
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let run = replay_run(dir.path());
    let (_server, url) = serve(&run);
    let plain = clean_shot(
        &chromium,
        &url,
        &shot_path(dir.path(), "view_plain.png"),
        &dir.path().join("profile_plain"),
    );
    let styled = clean_shot(
        &chromium,
        &format!("{url}?normals=1&look=reference"),
        &shot_path(dir.path(), "view_normals_reference.png"),
        &dir.path().join("profile_styled"),
    );
    assert_eq!(
        html_attr(&styled.dom, "data-normals").as_deref(),
        Some("1839")
    );
    assert_eq!(
        html_attr(&styled.dom, "data-look").as_deref(),
        Some("reference")
    );
    let half = WIDTH as usize / 2;
    // The reference look: white background, grey (r = g = b) shading in the 'after' view.
    let (w, h) = (styled.width, styled.height);
    assert_eq!(styled.pixel(half + 10, h / 2), [255, 255, 255]);
    let (mut grey, mut lit) = (0usize, 0usize);
    for (x, y) in styled.band(half, w) {
        let p = styled.pixel(x, y);
        if p != [255, 255, 255] {
            lit += 1;
            let spread = p.iter().max().unwrap() - p.iter().min().unwrap();
            grey += usize::from(spread <= 2);
        }
    }
    assert!(lit > 1000, "the mesh is not visible in the reference look");
    assert!(
        grey as f64 / lit as f64 > 0.95,
        "the reference look is not grey: {grey} of {lit} pixels"
    );
    // The normals field: coloured segments in the 'before' view only.
    let coloured = |shot: &Shot, x0: usize, x1: usize| {
        shot.band(x0, x1)
            .filter(|&(x, y)| {
                let p = shot.pixel(x, y);
                p.iter().max().unwrap() - p.iter().min().unwrap() > 60
            })
            .count()
    };
    assert!(
        coloured(&styled, 0, half) > 10 * coloured(&plain, 0, half).max(50),
        "no coloured normals field in the 'before' view"
    );
}

#[test]
fn gallery_lists_manifest_rows_and_filters() {
    let Some(chromium) = chromium() else {
        no_chromium();
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let run = replay_run(dir.path());
    // The run's own picture: a striped image.
    let (tw, th) = (96u32, 96u32);
    let mut rgb = Vec::new();
    for y in 0..th {
        for x in 0..tw {
            rgb.extend_from_slice(if (x / 12 + y / 12) % 2 == 0 {
                &[200, 40, 40]
            } else {
                &[40, 40, 200]
            });
        }
    }
    let file = std::fs::File::create(run.join("turntable.png")).unwrap();
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), tw, th);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.write_header().unwrap().write_image_data(&rgb).unwrap();
    let manifest = dir.path().join("batch.jsonl");
    std::fs::write(
        &manifest,
        "{\"mesh\": \"meshes/bunny.obj\", \"style\": \"cube\", \"out\": \"replay_run\"}\n\
         {\"mesh\": \"meshes/cow.off\", \"prompt\": \"a gothic cow\", \"out\": \"runs/cow\"}\n",
    )
    .unwrap();
    let (_server, url) = serve_all(&[&manifest]);
    let all = clean_shot(
        &chromium,
        &url,
        &shot_path(dir.path(), "view_gallery.png"),
        &dir.path().join("profile_all"),
    );
    assert_eq!(html_attr(&all.dom, "data-gallery").as_deref(), Some("2"));
    assert!(
        all.dom.contains("not started"),
        "the row not started is not marked"
    );
    assert!(all.dom.contains("a gothic cow"));
    // The thumbnail is drawn: red and blue stripes near the top left of the grid.
    let striped = all
        .band(0, WIDTH as usize / 2)
        .filter(|&(x, y)| {
            let p = all.pixel(x, y);
            p[0].abs_diff(p[2]) > 100
        })
        .count();
    assert!(
        striped > 2000,
        "the run's thumbnail is not shown ({striped} px)"
    );
    let filtered = clean_shot(
        &chromium,
        &format!("{url}?filter=gothic"),
        &shot_path(dir.path(), "view_gallery_filtered.png"),
        &dir.path().join("profile_filtered"),
    );
    assert_eq!(
        html_attr(&filtered.dom, "data-gallery").as_deref(),
        Some("1")
    );
}

#[test]
fn page_shows_the_mesh_and_follows_the_lambda_slider() {
    let Some(chromium) = chromium() else {
        eprintln!();
        eprintln!("############################################################################");
        eprintln!("SKIPPED view_browser: no chromium on PATH (install it: bash scripts/setup.sh,");
        eprintln!("or `apt-get install chromium`; or set CHROMIUM=/path/to/chrome)");
        eprintln!("############################################################################");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("bunny_run");
    std::fs::create_dir_all(&run).unwrap();
    std::fs::copy(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/golden/bunny_targets.npz"),
        run.join("deformation.npz"),
    )
    .unwrap();
    std::fs::write(run.join("run.json"), "{}").unwrap();
    let (_server, url) = serve(&run);
    let keep = std::env::var_os("STYLIZE_VIEW_SCREENSHOTS").map(PathBuf::from);
    let shots: Vec<Shot> = ["2", "16"]
        .iter()
        .map(|lambda| {
            let out = match &keep {
                Some(d) => {
                    std::fs::create_dir_all(d).unwrap();
                    d.join(format!("view_lambda{lambda}.png"))
                }
                None => dir.path().join(format!("view_lambda{lambda}.png")),
            };
            let shot = screenshot(
                &chromium,
                &format!("{url}?lambda={lambda}"),
                &out,
                &dir.path().join(format!("profile{lambda}")),
            );
            // The page reports through attributes of its <html> element.
            let html_tag = shot
                .dom
                .find("<html")
                .and_then(|i| shot.dom[i..].find('>').map(|j| &shot.dom[i..i + j]))
                .unwrap_or_default();
            assert!(
                html_tag.contains("data-state=\"ready\""),
                "λ = {lambda}: the page did not finish: {}",
                &shot.dom[..shot.dom.len().min(600)]
            );
            assert!(
                html_tag.contains(&format!("data-lambda=\"{lambda}\"")),
                "λ = {lambda}: the page shows another λ: {}",
                &shot.dom[..shot.dom.len().min(600)]
            );
            assert!(
                !html_tag.contains("data-errors"),
                "λ = {lambda}: page errors: {}",
                shot.dom
            );
            assert!(
                shot.console.is_empty(),
                "λ = {lambda}: console output: {:?}",
                shot.console
            );
            assert_eq!((shot.width, shot.height), (WIDTH as usize, HEIGHT as usize));
            shot
        })
        .collect();
    let half = WIDTH as usize / 2;
    for (shot, lambda) in shots.iter().zip(["2", "16"]) {
        let (left, right) = (shot.coverage(0, half), shot.coverage(half, 2 * half));
        assert!(
            left > 0.03 && right > 0.03,
            "λ = {lambda}: the mesh is not visible (coverage before {left:.4}, after {right:.4})"
        );
    }
    let before = shots[0].difference(&shots[1], 0, half);
    let after = shots[0].difference(&shots[1], half, 2 * half);
    assert!(
        before < 0.002,
        "the 'before' view changed with λ ({before:.4} of its pixels)"
    );
    assert!(
        after > 0.01,
        "the 'after' view did not change between λ = 2 and 16 ({after:.4} of its pixels)"
    );
    // Self-intersections: none at λ = 2; at λ = 16 the golden bunny crosses itself, the counts
    // are on the page and the new faces are drawn red over the result (only in 'after').
    let count = |shot: &Shot| -> u64 {
        html_attr(&shot.dom, "data-new-intersecting-faces")
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no count: {}", html_tag(&shot.dom)))
    };
    assert_eq!(count(&shots[0]), 0);
    assert!(count(&shots[1]) > 0);
    let red = |shot: &Shot, x0: usize, x1: usize| {
        shot.band(x0, x1)
            .filter(|&(x, y)| {
                let [r, g, b] = shot.pixel(x, y);
                r > 150 && g < 90 && b < 90
            })
            .count()
    };
    assert_eq!(red(&shots[0], 0, 2 * half), 0, "red pixels at λ = 2");
    assert_eq!(red(&shots[1], 0, half), 0, "red pixels in 'before'");
    assert!(
        red(&shots[1], half, 2 * half) > 20,
        "no red faces at λ = 16"
    );
    // The strongest safe λ up to the slider's end (20): λ = 8 is safe, 10 is not.
    for shot in &shots {
        let safe: f64 = html_attr(&shot.dom, "data-max-safe")
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no max-safe λ: {}", html_tag(&shot.dom)));
        assert!((8.0..10.0).contains(&safe), "{safe}");
    }
}

/// A run still being written (a lock, no `deformation.npz` yet) with two snapshots: the page
/// shows its first snapshot as "before" and its newest as "after", without errors.
#[test]
fn a_live_run_shows_its_newest_snapshot() {
    use npy::{NpyArray, NpyData};
    let Some(chromium) = chromium() else {
        no_chromium();
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("live_run");
    std::fs::create_dir_all(&run).unwrap();
    std::fs::write(run.join("task.json"), "{}").unwrap();
    std::fs::write(run.join("run.lock"), "{}").unwrap();
    let saved = stylize::saved::SavedDeformation::read(golden_npz()).unwrap();
    let x: Vec<f32> = (0..2)
        .flat_map(|k| {
            saved
                .verts
                .iter()
                .flat_map(move |p| [p[0], p[1] * (1.0 - 0.4 * k as f32), p[2]])
        })
        .collect();
    let it = NpyArray::new(vec![2], NpyData::I64(vec![0, 50])).unwrap();
    let xa = NpyArray::new(vec![2, saved.verts.len(), 3], NpyData::F32(x)).unwrap();
    let faces = NpyArray::i64_rows3(&saved.faces);
    npy::npz::write_npz(
        run.join("snapshots.npz"),
        [("iterations", &it), ("x", &xa), ("faces", &faces)],
    )
    .unwrap();
    let (_server, url) = serve(&run);
    let shot = clean_shot(
        &chromium,
        &url,
        &shot_path(dir.path(), "view_live_run.png"),
        &dir.path().join("profile_live"),
    );
    assert_eq!(html_attr(&shot.dom, "data-replay").as_deref(), Some("50"));
    assert!(shot.dom.contains("run · running"), "status not shown");
    let half = WIDTH as usize / 2;
    let (left, right) = (shot.coverage(0, half), shot.coverage(half, 2 * half));
    assert!(
        left > 0.03 && right > 0.03,
        "the live run is not drawn (before {left:.4}, after {right:.4})"
    );
    // The newest snapshot is flattened along y: less covered than the first.
    assert!(right < 0.9 * left, "before {left:.4}, after {right:.4}");
}

/// The strength slider (`?strength=S` through its own input handler): the page asks the server
/// for the result at λ pushed S times as far, reports it (`data-strength`), and the shape differs
/// from strength 1 in 'after' only.
#[test]
fn the_strength_slider_pushes_the_result_further() {
    let Some(chromium) = chromium() else {
        no_chromium();
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("bunny_run");
    std::fs::create_dir_all(&run).unwrap();
    std::fs::copy(golden_npz(), run.join("deformation.npz")).unwrap();
    std::fs::write(run.join("run.json"), "{}").unwrap();
    let (_server, url) = serve(&run);
    let shots: Vec<Shot> = ["1", "3"]
        .iter()
        .map(|s| {
            let shot = clean_shot(
                &chromium,
                &format!("{url}?lambda=8&strength={s}"),
                &dir.path().join(format!("strength{s}.png")),
                &dir.path().join(format!("profile{s}")),
            );
            let tag = html_tag(&shot.dom);
            assert!(tag.contains("data-state=\"ready\""), "strength {s}: {tag}");
            assert!(tag.contains("data-lambda=\"8\""), "strength {s}: {tag}");
            assert!(
                tag.contains(&format!("data-strength=\"{s}\"")),
                "strength {s}: {tag}"
            );
            assert_eq!(
                html_attr(&shot.dom, "data-new-intersecting-faces").as_deref(),
                Some("0"),
                "strength {s}: {tag}"
            );
            shot
        })
        .collect();
    let half = WIDTH as usize / 2;
    let before = shots[0].difference(&shots[1], 0, half);
    let after = shots[0].difference(&shots[1], half, 2 * half);
    eprintln!(
        "strength 1 → 3: {before:.4} of the before and {after:.4} of the after pixels differ"
    );
    assert!(
        before < 0.002,
        "'before' changed with the strength ({before:.4})"
    );
    assert!(
        after > 0.002,
        "'after' did not change with the strength ({after:.4})"
    );
}
