//! `stylize batch` writes the grid of its rows (2 meshes × 2 styles, one row failing), and
//! `stylize batch --grid-only` builds it after a sharded run: each tile against the run's own
//! `before_after.png` (its result square box-filtered to the tile, and the same mean colour), each
//! label's ink by position, and the empty tiles' statuses.
//!
//! Cost: 6 model-free runs of at most 3 iterations with 128-pixel pictures (a few seconds in a debug build).

use std::path::Path;

use mesh_core::TriMesh;
use raster_diff::Images;
use raster_diff::image::{Encoding, to_byte};
use stylize::runner::RunRequest;
use stylize::style::Style;
use stylize_cli::batch::read_manifest;
use stylize_cli::batch_grid::{
    CELL_HEIGHT, EMPTY_GREY, GUTTER, Layout, STATUS_INK, TEXT_SCALE, TILE, label_lines,
    label_origins, status_origin, tile_origin,
};
use stylize_cli::config::Config;
use stylize_cli::runner::{LogMode, execute};
use stylize_cli::sheet::{label_mask, resample};

mod common;
use common::{ok, s, stylize_text};

/// RGB8 pixels of a PNG.
struct Picture {
    width: usize,
    height: usize,
    px: Vec<u8>,
}

impl Picture {
    fn read(path: &Path) -> Self {
        let decoder = png::Decoder::new(std::io::BufReader::new(ok(std::fs::File::open(path))));
        let mut reader = ok(decoder.read_info());
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = ok(reader.next_frame(&mut buf));
        assert_eq!(info.color_type, png::ColorType::Rgb, "{}", path.display());
        buf.truncate(info.buffer_size());
        Self {
            width: info.width as usize,
            height: info.height as usize,
            px: buf,
        }
    }

    fn at(&self, x: usize, y: usize) -> [u8; 3] {
        let i = (y * self.width + x) * 3;
        [self.px[i], self.px[i + 1], self.px[i + 2]]
    }
}

fn bytes(rgb: [f32; 3]) -> [u8; 3] {
    rgb.map(|v| to_byte(v, Encoding::Direct))
}

const SETTINGS: &[&str] = &[
    "--quiet",
    "--set",
    "style.iterations=3",
    "--set",
    "run.checkpoint_every=2",
    "--set",
    "run.preview_every=0",
    "--set",
    "run.turntable_views=1",
    "--set",
    "run.turntable_size=128",
    "--set",
    "run.turntable_gif_frames=0",
];

/// Two meshes (`m.obj`, `n.obj`) and `batch.toml`: m × cube, m × octahedron, n × cube, and
/// n × octahedron with a refused λ (that row fails).
fn setup(dir: &Path) {
    let (p, f) = mesh_core::shapes::icosphere(1).into_parts();
    for (name, sx, sy) in [("m.obj", 1.3, 1.0), ("n.obj", 1.0, 1.6)] {
        let q: Vec<[f64; 3]> = p.iter().map(|v| [sx * v[0], sy * v[1], v[2]]).collect();
        ok(mesh_core::io::write_mesh(
            dir.join(name),
            &TriMesh::new(q, f.clone()),
            None,
        ));
    }
    let manifest = "[[run]]\nmesh = \"m.obj\"\nstyle = \"cube\"\nout = \"runs/m-cube\"\n\n\
                    [[run]]\nmesh = \"m.obj\"\nstyle = \"octahedron\"\nout = \"runs/m-octa\"\n\n\
                    [[run]]\nmesh = \"n.obj\"\nstyle = \"cube\"\nout = \"runs/n-cube\"\n\n\
                    [[run]]\nmesh = \"n.obj\"\nstyle = \"octahedron\"\nout = \"runs/n-octa\"\n\
                    overrides = [\"darap.lambda=-1\"]\n";
    ok(std::fs::write(dir.join("batch.toml"), manifest));
}

/// The cell of manifest row `i`.
fn cell(manifest: &Path, i: usize) -> (usize, usize) {
    Layout::of(&ok(read_manifest(manifest))).cell_of_row[i]
}

/// Row `i`'s tile is its run's result square (`before_after.png`: two rows of squares, the
/// result's first view bottom-left) box-filtered to the tile: equal to [`resample`] of that square
/// of the picture as read here, of the same mean colour (within 1.5 levels of 255), and not blank.
fn check_result_tile(grid: &Picture, manifest: &Path, i: usize, run_dir: &Path) {
    let ba = Picture::read(&run_dir.join("before_after.png"));
    let side = ba.height / 2;
    assert!(
        side > 16 && ba.height.is_multiple_of(2) && ba.width >= side,
        "two rows of squares"
    );
    let picture = Images {
        count: 1,
        height: ba.height,
        width: ba.width,
        channels: 3,
        rgb: ba.px.iter().map(|&b| f32::from(b) / 255.0).collect(),
    };
    let want = ok(resample(&picture, 0, (0, side, side), TILE));
    let (x0, y0) = tile_origin(cell(manifest, i));
    let mut not_white = 0;
    let mut sum_tile = [0.0f64; 3];
    for y in 0..TILE {
        for x in 0..TILE {
            let w = [0, 1, 2].map(|c| to_byte(want.rgb[(y * TILE + x) * 3 + c], Encoding::Direct));
            let got = grid.at(x0 + x, y0 + y);
            assert_eq!(got, w, "row {i} tile at ({x}, {y})");
            not_white += usize::from(got != [255; 3]);
            for c in 0..3 {
                sum_tile[c] += f64::from(got[c]);
            }
        }
    }
    assert!(not_white > TILE * TILE / 20, "row {i}: a visible result");
    let mut sum_square = [0.0f64; 3];
    for y in side..2 * side {
        for x in 0..side {
            for c in 0..3 {
                sum_square[c] += f64::from(ba.at(x, y)[c]);
            }
        }
    }
    for c in 0..3 {
        let (a, b) = (
            sum_tile[c] / (TILE * TILE) as f64,
            sum_square[c] / (side * side) as f64,
        );
        assert!(
            (a - b).abs() < 1.5,
            "row {i} channel {c}: mean {a} against {b}"
        );
    }
}

/// Row `i`'s label band: black exactly on the glyphs of its two lines, white elsewhere.
fn check_labels(grid: &Picture, manifest: &Path, i: usize, want: [&str; 2]) {
    let rows = ok(read_manifest(manifest));
    let layout = Layout::of(&rows);
    let c = layout.cell_of_row[i];
    let lines = label_lines(&layout.mesh_labels[i], &rows[i], &layout.suffixes[i]);
    assert_eq!(lines, want.map(String::from));
    let origins = label_origins(c, &lines);
    let (x0, y0) = tile_origin(c);
    let mut ink = 0;
    for y in y0 + TILE..y0 + CELL_HEIGHT {
        for x in x0..x0 + TILE {
            let on_glyph = lines.iter().zip(origins).any(|(text, (lx, ly))| {
                let (w, h, mask) = label_mask(text, TEXT_SCALE);
                (lx..lx + w).contains(&x)
                    && (ly..ly + h).contains(&y)
                    && mask[(y - ly) * w + x - lx]
            });
            let want = if on_glyph { [0; 3] } else { [255; 3] };
            assert_eq!(grid.at(x, y), want, "row {i} label at ({x}, {y})");
            ink += usize::from(on_glyph);
        }
    }
    assert!(ink > 0, "row {i}: a label is drawn");
}

/// Row `i`'s tile is grey with `status` in red at its place.
fn check_empty_tile(grid: &Picture, manifest: &Path, i: usize, status: &str) {
    let c = cell(manifest, i);
    let (x0, y0) = tile_origin(c);
    let (sx, sy) = status_origin(c, status);
    let (w, h, mask) = label_mask(status, TEXT_SCALE);
    let mut ink = 0;
    for y in y0..y0 + TILE {
        for x in x0..x0 + TILE {
            let on = (sx..sx + w).contains(&x)
                && (sy..sy + h).contains(&y)
                && mask[(y - sy) * w + x - sx];
            let want = bytes(if on { STATUS_INK } else { EMPTY_GREY });
            assert_eq!(grid.at(x, y), want, "row {i} ({status}) at ({x}, {y})");
            ink += usize::from(on);
        }
    }
    assert!(ink > 0);
}

#[test]
fn a_batch_writes_the_labelled_grid_of_its_rows_with_its_failed_row_marked() {
    let tmp = ok(tempfile::tempdir());
    let dir = tmp.path();
    setup(dir);
    let manifest = dir.join("batch.toml");
    let mut args = vec!["batch", s(&manifest)];
    args.extend_from_slice(SETTINGS);
    let (success, _, err) = stylize_text(&args);
    assert!(!success, "a row fails: {err}");
    assert!(err.contains("row 3") && err.contains("FAILED"), "{err}");
    let path = dir.join("batch_grid.png");
    assert!(err.contains(&format!("grid: {}", path.display())), "{err}");
    let grid = Picture::read(&path);
    assert_eq!(
        (grid.width, grid.height),
        (2 * TILE + GUTTER, 2 * CELL_HEIGHT + GUTTER)
    );
    // The gutters between cells are white.
    for y in 0..grid.height {
        for x in 0..grid.width {
            if (TILE..TILE + GUTTER).contains(&x)
                || (CELL_HEIGHT..CELL_HEIGHT + GUTTER).contains(&y)
            {
                assert_eq!(grid.at(x, y), [255; 3], "gutter at ({x}, {y})");
            }
        }
    }
    // Lines = meshes, columns = styles.
    assert_eq!(
        (0..4).map(|i| cell(&manifest, i)).collect::<Vec<_>>(),
        [(0, 0), (0, 1), (1, 0), (1, 1)]
    );
    for (i, run) in [(0, "m-cube"), (1, "m-octa"), (2, "n-cube")] {
        check_result_tile(&grid, &manifest, i, &dir.join("runs").join(run));
    }
    check_empty_tile(&grid, &manifest, 3, "FAILED");
    check_labels(&grid, &manifest, 0, ["m", "cube"]);
    check_labels(&grid, &manifest, 1, ["m", "octahedron"]);
    check_labels(&grid, &manifest, 2, ["n", "cube"]);
    check_labels(&grid, &manifest, 3, ["n", "octahedron"]);
}

#[test]
fn after_a_sharded_run_grid_only_builds_the_grid_from_the_run_directories() {
    let tmp = ok(tempfile::tempdir());
    let dir = tmp.path();
    setup(dir);
    let manifest = dir.join("batch.toml");
    // Shard 0/2 runs rows 0 and 2 (the cubes) and writes no grid: its end is not the batch's.
    let mut args = vec!["batch", s(&manifest), "--shard", "0/2"];
    args.extend_from_slice(SETTINGS);
    let (success, _, err) = stylize_text(&args);
    assert!(success, "{err}");
    assert!(err.contains("--grid-only"), "{err}");
    assert!(!dir.join("batch_grid.png").exists());
    let path = dir.join("sheets/grid.png");
    let (success, _, err) =
        stylize_text(&["batch", s(&manifest), "--grid-only", "--grid", s(&path)]);
    assert!(success, "{err}");
    assert!(err.contains("2 with a result, 2 without"), "{err}");
    let grid = Picture::read(&path);
    assert_eq!(
        (grid.width, grid.height),
        (2 * TILE + GUTTER, 2 * CELL_HEIGHT + GUTTER)
    );
    check_result_tile(&grid, &manifest, 0, &dir.join("runs/m-cube"));
    check_result_tile(&grid, &manifest, 2, &dir.join("runs/n-cube"));
    check_empty_tile(&grid, &manifest, 1, "NOT RUN");
    check_empty_tile(&grid, &manifest, 3, "NOT RUN");
    check_labels(&grid, &manifest, 3, ["n", "octahedron"]);
    // The row edited since (m × cube → m × exemplar n.obj) no longer shows the cube result.
    let edited = ok(std::fs::read_to_string(&manifest)).replacen(
        "style = \"cube\"",
        "style = \"exemplar:n.obj\"",
        1,
    );
    ok(std::fs::write(&manifest, edited));
    let (success, _, err) =
        stylize_text(&["batch", s(&manifest), "--grid-only", "--grid", s(&path)]);
    assert!(success, "{err}");
    let grid = Picture::read(&path);
    check_empty_tile(&grid, &manifest, 0, "OTHER TASK");
    check_labels(&grid, &manifest, 0, ["m", "exemplar:n.obj"]);
    check_result_tile(&grid, &manifest, 2, &dir.join("runs/n-cube"));
    // A run stopped after its checkpoint (row 1, m × octahedron, halted at iteration 2): PARTIAL.
    let mut config = Config::default();
    config.style.iterations = 3;
    config.run.checkpoint_every = 2;
    config.run.preview_every = 0;
    ok(execute(
        &RunRequest {
            mesh: dir.join("m.obj"),
            out: dir.join("runs/m-octa"),
            config,
            force: false,
            resume: false,
            halt_after: Some(2),
        },
        LogMode::Quiet,
        Style::Octahedron,
    ));
    assert!(dir.join("runs/m-octa/checkpoint.json").is_file());
    let (success, _, err) =
        stylize_text(&["batch", s(&manifest), "--grid-only", "--grid", s(&path)]);
    assert!(success, "{err}");
    check_empty_tile(&Picture::read(&path), &manifest, 1, "PARTIAL");
    // --grid-only runs nothing: it cannot be sharded or forced.
    let (success, _, err) = stylize_text(&["batch", s(&manifest), "--grid-only", "--shard", "0/2"]);
    assert!(!success && err.contains("--shard"), "{err}");
    // A grid never replaces the manifest or a run's own pictures; nothing is written then.
    let before = ok(std::fs::read(&manifest));
    let (success, _, err) =
        stylize_text(&["batch", s(&manifest), "--grid-only", "--grid", s(&manifest)]);
    assert!(!success && err.contains(".png"), "{err}");
    assert_eq!(ok(std::fs::read(&manifest)), before);
    let inside = dir.join("runs/n-cube/before_after.png");
    let picture = ok(std::fs::read(&inside));
    let (success, _, err) =
        stylize_text(&["batch", s(&manifest), "--grid-only", "--grid", s(&inside)]);
    assert!(!success && err.contains("row 2's run directory"), "{err}");
    assert_eq!(ok(std::fs::read(&inside)), picture);
    // A complete run whose picture is gone (or damaged) is a NO RENDER tile, not an error.
    ok(std::fs::write(&inside, b"not a png"));
    let (success, _, err) =
        stylize_text(&["batch", s(&manifest), "--grid-only", "--grid", s(&path)]);
    assert!(success, "{err}");
    check_empty_tile(&Picture::read(&path), &manifest, 2, "NO RENDER");
}

#[test]
fn a_batch_of_more_than_400_rows_draws_no_grid_unless_asked() {
    let tmp = ok(tempfile::tempdir());
    let dir = tmp.path();
    setup(dir);
    // 401 rows that each fail at once (a refused λ): no run, no tile is ever read.
    let mut manifest = String::new();
    for i in 0..401 {
        manifest.push_str(&format!(
            "[[run]]\nmesh = \"m.obj\"\nstyle = \"cube\"\nout = \"runs/r{i}\"\n\
             overrides = [\"darap.lambda=-1\"]\n\n"
        ));
    }
    let path = dir.join("many.toml");
    ok(std::fs::write(&path, manifest));
    let mut args = vec!["batch", s(&path)];
    args.extend_from_slice(SETTINGS);
    let (success, _, err) = stylize_text(&args);
    assert!(!success, "every row fails: {err}");
    assert!(
        err.contains("grid: none (401 rows, more than the 400"),
        "{err}"
    );
    assert!(!dir.join("many_grid.png").exists());
}

#[test]
fn the_default_grid_failing_is_a_warning_and_an_asked_for_grid_failing_an_error() {
    let tmp = ok(tempfile::tempdir());
    let dir = tmp.path();
    setup(dir);
    let manifest = dir.join("one.toml");
    ok(std::fs::write(
        &manifest,
        "[[run]]\nmesh = \"m.obj\"\nstyle = \"cube\"\nout = \"runs/m-cube\"\n",
    ));
    // A folder where the default grid would go: the PNG cannot be written there.
    ok(std::fs::create_dir(dir.join("one_grid.png")));
    let mut args = vec!["batch", s(&manifest)];
    args.extend_from_slice(SETTINGS);
    let (success, _, err) = stylize_text(&args);
    assert!(
        success,
        "the row is done; the default grid is a by-product: {err}"
    );
    assert!(err.contains("warning: grid: not written"), "{err}");
    // The same grid asked for: the batch fails (its row stays done: skipped as complete).
    let blocked = dir.join("one_grid.png");
    let mut args = vec!["batch", s(&manifest), "--grid", s(&blocked)];
    args.extend_from_slice(SETTINGS);
    let (success, _, err) = stylize_text(&args);
    assert!(!success, "{err}");
    assert!(
        err.contains("grid: not written") && err.contains("the grid could not be written"),
        "{err}"
    );
    assert!(dir.join("runs/m-cube/mesh.obj").is_file());
}
