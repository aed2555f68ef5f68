//! The grid of a batch's rows: `MANIFEST_STEM_grid.png` beside the manifest (or `--grid FILE`),
//! one labelled tile per row, for papers and reviews. Written at the end of an unsharded
//! `stylize batch` and by `stylize batch MANIFEST --grid-only`, which builds it from the run
//! directories as they stand (the step after the last shard of a sharded batch).
//!
//! **Layout** ([`Layout::of`]). A *table*: one line per distinct mesh (in order of first
//! appearance), one column per distinct prompt/style (likewise; a mesh with the same prompt/style
//! in `k` rows — other seeds, say — fills `k` columns of that prompt/style). When that table would
//! be less than half filled (every mesh with its own prompt, say), a *list* instead: the rows in
//! manifest order, ⌈√n⌉ tiles per line.
//!
//! **A cell** ([`GUTTER`] white pixels between neighbours) is a [`TILE`]-pixel square above a
//! white band of [`LABEL_HEIGHT`] pixels with two
//! lines in black, each centred and shortened with `…` to the tile's width ([`crate::sheet`]'s
//! font at ×[`TEXT_SCALE`]): the mesh's name (file stem; the parent folder too when two meshes share
//! a stem) and the prompt/style (`exemplar:FILE` by file name), with [`Layout::suffixes`] telling
//! apart rows of the same mesh and prompt/style (` seed 7`, ` #2`).
//!
//! **The tile** of a row whose run is complete and of the row's prompt/style is the result's first
//! view in the run's `before_after.png` (its bottom-left square: the bottom row is the result,
//! squares of the picture's half height), box-filtered to [`TILE`] pixels ([`sheet::resample`]) —
//! nothing is rendered again. Any other row gets a grey ([`EMPTY_GREY`]) tile with its status in
//! red ([`STATUS_INK`]), centred: `FAILED`, `IN USE`, `INTERRUPTED` (known only to the batch that
//! ran the row), `NOT RUN` (no run directory), `PARTIAL` (a checkpoint, no result yet), `NOT DONE`
//! (a run directory without checkpoint or result), `OTHER TASK` (a complete run whose `task.json`
//! names another objective, style or prompt than the row: the row was edited since; the batch
//! itself compares the whole identity, this check only the objective's fields), `NO RENDER`
//! (`before_after.png` missing or unreadable). A table cell no row fills stays white, with `no
//! row` in grey.

use std::path::{Path, PathBuf};

use anyhow::bail;
use raster_diff::Images;
use rundir::RunDir;
use stylize::task::TaskKind;

use crate::batch::{Row, RowStatus};
use crate::sheet::{self, Canvas};

/// Tile side in pixels.
pub const TILE: usize = 256;
/// Pixels per font pixel of the labels and statuses.
pub const TEXT_SCALE: usize = 2;
/// Space above, between and below the two label lines.
pub const LABEL_PAD: usize = 4;
/// Height of the label band under each tile: two lines of text and three pads.
pub const LABEL_HEIGHT: usize = 3 * LABEL_PAD + 2 * sheet::GLYPH_ROWS * TEXT_SCALE;
/// Height of a cell: the tile and its label band.
pub const CELL_HEIGHT: usize = TILE + LABEL_HEIGHT;
/// White space between neighbouring cells (none around the sheet).
pub const GUTTER: usize = 8;
/// Fill of a tile without a result.
pub const EMPTY_GREY: [f32; 3] = [0.85, 0.85, 0.85];
/// Ink of the status on an empty tile.
pub const STATUS_INK: [f32; 3] = [0.75, 0.0, 0.0];
/// Ink of `no row`.
pub const NO_ROW_INK: [f32; 3] = [0.6, 0.6, 0.6];
/// The largest sheet written, in pixels (about 8,000 × 8,000: some 900 tiles, far beyond a paper
/// figure; the canvas is `f32` RGB, so this bounds it near 800 MB). A larger grid is refused with a
/// message, before any tile is read, rather than allocating gigabytes.
pub const MAX_SHEET_PIXELS: usize = 1 << 26;
/// The most rows a batch draws a grid of without being asked (`--grid`): beyond that a sheet is no
/// longer a figure anyone reads, and a large cluster batch should not pay for one.
pub const DEFAULT_GRID_MAX_ROWS: usize = 400;

/// The sheet's default path for a manifest: `MANIFEST_STEM_grid.png` in the manifest's folder.
pub fn default_path(manifest: &Path) -> PathBuf {
    let stem = manifest
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "batch".into());
    manifest.with_file_name(format!("{stem}_grid.png"))
}

/// Refuses a grid path that could replace something else: a name not ending in `.png` (the
/// manifest, a mesh), or a file inside a row's run directory (its own pictures).
pub fn check_path(path: &Path, rows: &[Row]) -> anyhow::Result<()> {
    if !path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
    {
        bail!(
            "the grid {} must be a .png file (a grid never replaces another kind of file)",
            path.display()
        );
    }
    let grid = crate::batch::normalize_lexically(&absolute(path));
    for (i, r) in rows.iter().enumerate() {
        if grid.starts_with(crate::batch::normalize_lexically(&absolute(&r.out))) {
            bail!(
                "the grid {} lies inside row {i}'s run directory {}; put it beside the manifest \
                 or elsewhere",
                path.display(),
                r.out.display()
            );
        }
    }
    Ok(())
}

fn absolute(p: &Path) -> PathBuf {
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        std::env::current_dir()
            .map(|d| d.join(p))
            .unwrap_or_else(|_| p.to_path_buf())
    }
}

/// A row's prompt or style as its label says it: the prompt's text, `cube`, `octahedron`, or
/// `exemplar:` with the exemplar's file name.
pub fn style_label(row: &Row) -> String {
    if let Some(p) = &row.prompt {
        return p.clone();
    }
    let style = row.style.as_deref().unwrap_or_default().trim();
    match style.strip_prefix("exemplar:") {
        Some(file) => format!(
            "exemplar:{}",
            Path::new(file)
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| file.to_string())
        ),
        None => style.to_string(),
    }
}

/// Where each row's cell is, and the labels.
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    /// Cells per line.
    pub columns: usize,
    /// Lines of cells.
    pub lines: usize,
    /// Each row's cell: `(line, column)`, indexed like the manifest's rows.
    pub cell_of_row: Vec<(usize, usize)>,
    /// Whether this is the mesh × prompt/style table (false: the list).
    pub table: bool,
    /// Each row's mesh label.
    pub mesh_labels: Vec<String>,
    /// What tells apart rows of the same mesh and prompt/style, after the prompt/style on the
    /// label: ` seed N` when they all have a seed and no two the same, ` #k` (the k-th such row)
    /// otherwise; empty for a row whose pair is unique.
    pub suffixes: Vec<String>,
}

impl Layout {
    /// The layout of the module documentation for the manifest's rows.
    pub fn of(rows: &[Row]) -> Self {
        let key = |r: &Row| crate::batch::normalize_lexically(&r.mesh);
        let mut meshes: Vec<PathBuf> = Vec::new();
        for r in rows {
            if !meshes.contains(&key(r)) {
                meshes.push(key(r));
            }
        }
        // Mesh labels: the file stem, with its parent folder when stems collide.
        let stem = |p: &Path| {
            p.file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| p.display().to_string())
        };
        let label_of = |p: &Path| {
            let s = stem(p);
            let collides = meshes.iter().any(|m| m != p && stem(m) == s);
            match p.parent().and_then(|d| d.file_name()) {
                Some(d) if collides => format!("{}/{s}", d.to_string_lossy()),
                _ => s,
            }
        };
        let mesh_labels: Vec<String> = rows.iter().map(|r| label_of(&key(r))).collect();
        // Columns: (prompt/style, occurrence of that pair for the mesh).
        let mut columns: Vec<(String, usize)> = Vec::new();
        let mut cell_of_row = Vec::with_capacity(rows.len());
        for (i, r) in rows.iter().enumerate() {
            let label = style_label(r);
            let m = meshes.iter().position(|k| *k == key(r)).unwrap_or(0);
            let occurrence = rows[..i]
                .iter()
                .filter(|o| key(o) == key(r) && style_label(o) == label)
                .count();
            let column = (label, occurrence);
            let j = match columns.iter().position(|c| *c == column) {
                Some(j) => j,
                None => {
                    columns.push(column);
                    columns.len() - 1
                }
            };
            cell_of_row.push((m, j));
        }
        let suffixes: Vec<String> = rows
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let same: Vec<&Row> = rows
                    .iter()
                    .filter(|o| key(o) == key(r) && style_label(o) == style_label(r))
                    .collect();
                if same.len() < 2 {
                    return String::new();
                }
                let seeds_differ = same.iter().all(|o| o.seed.is_some())
                    && same
                        .iter()
                        .enumerate()
                        .all(|(a, o)| same[..a].iter().all(|p| p.seed != o.seed));
                match r.seed {
                    Some(seed) if seeds_differ => format!(" seed {seed}"),
                    _ => format!(" #{}", columns[cell_of_row[i].1].1 + 1),
                }
            })
            .collect();
        let cells = meshes.len() * columns.len();
        if rows.is_empty() || 2 * rows.len() >= cells {
            return Self {
                columns: columns.len(),
                lines: meshes.len(),
                cell_of_row,
                table: true,
                mesh_labels,
                suffixes,
            };
        }
        let per_line = (1..=rows.len()).find(|c| c * c >= rows.len()).unwrap_or(1);
        Self {
            columns: per_line,
            lines: rows.len().div_ceil(per_line),
            cell_of_row: (0..rows.len())
                .map(|i| (i / per_line, i % per_line))
                .collect(),
            table: false,
            mesh_labels,
            suffixes,
        }
    }

    /// The sheet's size in pixels.
    pub fn size(&self) -> (usize, usize) {
        let span = |n: usize, cell: usize| (n * (cell + GUTTER)).saturating_sub(GUTTER);
        (span(self.columns, TILE), span(self.lines, CELL_HEIGHT))
    }
}

/// The top-left corner of cell `(line, column)`'s tile.
pub fn tile_origin((line, column): (usize, usize)) -> (usize, usize) {
    (column * (TILE + GUTTER), line * (CELL_HEIGHT + GUTTER))
}

/// The two label lines of a row's cell, shortened to the tile's width: the mesh label, and the
/// prompt/style followed by `suffix` ([`Layout::suffixes`], kept whole: the prompt/style is
/// shortened).
pub fn label_lines(mesh_label: &str, row: &Row, suffix: &str) -> [String; 2] {
    let width = TILE - 2 * LABEL_PAD;
    let fit = |t: &str, w: usize| sheet::fit_text(t, w, TEXT_SCALE);
    // Joining two texts adds one font pixel of space between them.
    let room = match suffix {
        "" => width,
        _ => width.saturating_sub(sheet::text_width(suffix, TEXT_SCALE) + TEXT_SCALE),
    };
    [
        fit(mesh_label, width),
        fit(&(fit(&style_label(row), room) + suffix), width),
    ]
}

/// The top-left corners of the label lines' masks in cell `cell`.
pub fn label_origins(cell: (usize, usize), lines: &[String; 2]) -> [(usize, usize); 2] {
    let (x0, y0) = tile_origin(cell);
    let line_h = sheet::GLYPH_ROWS * TEXT_SCALE;
    let y = [y0 + TILE + LABEL_PAD, y0 + TILE + 2 * LABEL_PAD + line_h];
    [
        (sheet::centred(x0, TILE, &lines[0], TEXT_SCALE), y[0]),
        (sheet::centred(x0, TILE, &lines[1], TEXT_SCALE), y[1]),
    ]
}

/// The top-left corner of an empty tile's status text.
pub fn status_origin(cell: (usize, usize), status: &str) -> (usize, usize) {
    let (x0, y0) = tile_origin(cell);
    (
        sheet::centred(x0, TILE, status, TEXT_SCALE),
        y0 + (TILE - sheet::GLYPH_ROWS * TEXT_SCALE) / 2,
    )
}

/// What a row's tile shows.
#[derive(Clone, Debug, PartialEq)]
pub enum Tile {
    /// The result, [`TILE`]×[`TILE`].
    Result(Images),
    /// No result: the status word of the module documentation.
    Empty(&'static str),
}

/// The square `(x0, y0, side)` of the result's first view in a `before_after.png` of `width` ×
/// `height` pixels (bottom-left; side = half the height).
pub fn result_square(width: usize, height: usize) -> anyhow::Result<(usize, usize, usize)> {
    let side = height / 2;
    if side == 0 || !height.is_multiple_of(2) || width < side {
        bail!("a before/after picture of {width}×{height} pixels is not two rows of square tiles");
    }
    Ok((0, side, side))
}

/// The tile of `row` from its run directory; `known` is the row's outcome in the batch that just
/// ran it (`FAILED`, `IN USE`, `INTERRUPTED` come only from there).
pub fn row_tile(row: &Row, known: Option<&RowStatus>) -> Tile {
    match known {
        Some(RowStatus::Failed(_)) => return Tile::Empty("FAILED"),
        Some(RowStatus::InUse(_)) => return Tile::Empty("IN USE"),
        Some(RowStatus::Interrupted(_)) => return Tile::Empty("INTERRUPTED"),
        _ => {}
    }
    let dir = RunDir::new(&row.out);
    if !dir.is_complete() {
        return Tile::Empty(if dir.has_checkpoint() {
            "PARTIAL"
        } else if row.out.exists() {
            "NOT DONE"
        } else {
            "NOT RUN"
        });
    }
    if !same_objective(row, &dir) {
        return Tile::Empty("OTHER TASK");
    }
    let tile = sheet::read_png_region(&dir.file("before_after.png"), |w, h| {
        let (x0, y0, side) = result_square(w, h)?;
        Ok((x0, y0, side, side))
    })
    .and_then(|square| sheet::resample(&square, 0, (0, 0, square.width), TILE));
    match tile {
        Ok(t) => Tile::Result(t),
        Err(_) => Tile::Empty("NO RENDER"),
    }
}

/// Whether the identity in the run directory's `task.json` has the row's objective fields
/// (`objective` and `style`/exemplar hash, or `objective` and `prompt`); a style that cannot be
/// read (a missing exemplar) is not the same.
fn same_objective(row: &Row, dir: &RunDir) -> bool {
    let Some(identity) = dir.task_identity() else {
        return false;
    };
    let fields = match (&row.style, &row.prompt) {
        (Some(style), _) => match stylize::style::Style::parse(style) {
            Ok(s) => s.identity_fields(),
            Err(_) => return false,
        },
        (None, Some(text)) => stylize::task::Prompt {
            text: text.clone(),
            model: None,
        }
        .identity_fields(),
        (None, None) => return false,
    };
    fields
        .iter()
        .all(|(k, v)| identity.fields.get(k) == Some(v))
}

/// Counts of a written sheet.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridCounts {
    /// Tiles with a result.
    pub results: usize,
    /// Tiles without one.
    pub empty: usize,
}

/// Refuses a grid of `rows` (laid out as `layout`) larger than [`MAX_SHEET_PIXELS`]; called
/// before any tile is read.
fn check_size(layout: &Layout, rows: usize) -> anyhow::Result<()> {
    let (w, h) = layout.size();
    if w.saturating_mul(h) > MAX_SHEET_PIXELS {
        bail!(
            "the grid of {rows} rows would be {w}×{h} pixels, more than the {MAX_SHEET_PIXELS} \
             written (split the manifest)"
        );
    }
    Ok(())
}

/// The sheet of `rows`, laid out as `layout` (of a size [`check_size`] accepted), with the tiles
/// `tiles` (one per row, in order).
fn sheet_of(rows: &[Row], layout: &Layout, tiles: &[Tile]) -> Images {
    let (w, h) = layout.size();
    let mut canvas = Canvas::new(w, h);
    if layout.table {
        let filled = &layout.cell_of_row;
        for line in 0..layout.lines {
            for column in 0..layout.columns {
                if !filled.contains(&(line, column)) {
                    let (x, y) = status_origin((line, column), "no row");
                    canvas.draw_text("no row", TEXT_SCALE, x, y, NO_ROW_INK);
                }
            }
        }
    }
    for (i, (row, tile)) in rows.iter().zip(tiles).enumerate() {
        let cell = layout.cell_of_row[i];
        let (x0, y0) = tile_origin(cell);
        match tile {
            Tile::Result(image) => canvas.paste(image, 0, x0, y0),
            Tile::Empty(status) => {
                canvas.fill(x0, y0, TILE, TILE, EMPTY_GREY);
                let (x, y) = status_origin(cell, status);
                canvas.draw_text(status, TEXT_SCALE, x, y, STATUS_INK);
            }
        }
        let lines = label_lines(&layout.mesh_labels[i], row, &layout.suffixes[i]);
        for (text, (x, y)) in lines.iter().zip(label_origins(cell, &lines)) {
            canvas.draw_text(text, TEXT_SCALE, x, y, [0.0; 3]);
        }
    }
    canvas.into_images()
}

/// Builds and writes (atomically) the sheet of every row of the manifest at `path`; `known` holds
/// the outcomes of the rows the calling batch ran (by manifest index).
pub fn write_grid(
    path: &Path,
    rows: &[Row],
    known: &[(usize, RowStatus)],
) -> anyhow::Result<GridCounts> {
    check_path(path, rows)?;
    if rows.is_empty() {
        bail!("the manifest has no rows");
    }
    let layout = Layout::of(rows);
    check_size(&layout, rows.len())?;
    let tiles: Vec<Tile> = rows
        .iter()
        .enumerate()
        .map(|(i, r)| row_tile(r, known.iter().find(|(k, _)| *k == i).map(|(_, s)| s)))
        .collect();
    let sheet = sheet_of(rows, &layout, &tiles);
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .map_err(|e| anyhow::anyhow!("cannot create {}: {e}", parent.display()))?;
    }
    stylize::run_pictures::write_png_atomic(path, &sheet)
        .map_err(|e| anyhow::anyhow!("cannot write the grid {}: {e:#}", path.display()))?;
    let results = tiles
        .iter()
        .filter(|t| matches!(t, Tile::Result(_)))
        .count();
    Ok(GridCounts {
        results,
        empty: tiles.len() - results,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(mesh: &str, style: &str) -> Row {
        Row {
            mesh: PathBuf::from(mesh),
            out: PathBuf::from(format!("runs/{mesh}-{style}")),
            prompt: None,
            style: Some(style.into()),
            negative_prompt: None,
            seed: None,
            overrides: vec![],
            region: vec![],
            region_feather: None,
            remesh: None,
            up: None,
            output_frame: None,
            camera: None,
        }
    }

    #[test]
    fn meshes_are_lines_styles_columns_and_a_sparse_table_becomes_a_list() {
        let rows = [
            row("a/bunny.obj", "cube"),
            row("b/bunny.obj", "cube"),
            row("a/bunny.obj", "octahedron"),
            row("b/bunny.obj", "octahedron"),
            row("a/./bunny.obj", "cube"),
        ];
        let l = Layout::of(&rows);
        assert!(l.table);
        assert_eq!((l.lines, l.columns), (2, 3));
        // Columns (cube, 0), (octahedron, 0), (cube, 1): the second cube row of a/bunny.
        assert_eq!(l.cell_of_row, [(0, 0), (1, 0), (0, 1), (1, 1), (0, 2)]);
        assert_eq!(
            l.mesh_labels,
            ["a/bunny", "b/bunny", "a/bunny", "b/bunny", "a/bunny"]
        );
        // Two cube rows of a/bunny (no seeds): told apart by their number.
        assert_eq!(l.suffixes, [" #1", "", "", "", " #2"]);
        let mut seeded = rows.to_vec();
        seeded[0].seed = Some(1);
        seeded[4].seed = Some(7);
        assert_eq!(
            Layout::of(&seeded).suffixes,
            [" seed 1", "", "", "", " seed 7"]
        );
        // The same seed twice (other overrides, say): numbers again.
        seeded[4].seed = Some(1);
        assert_eq!(Layout::of(&seeded).suffixes, [" #1", "", "", "", " #2"]);
        let long = Row {
            prompt: Some("a bunny made of lego bricks, studio lighting".into()),
            style: None,
            ..row("m.obj", "")
        };
        let lines = label_lines("m", &long, " seed 12");
        assert!(lines[1].ends_with("… seed 12"), "{}", lines[1]);
        assert!(sheet::text_width(&lines[1], TEXT_SCALE) <= TILE - 2 * LABEL_PAD);
        assert_eq!(
            style_label(&row("cow.off", "exemplar:/x/shapes/e.obj")),
            "exemplar:e.obj"
        );
        // Every mesh with its own style: a 4×4 table would be a quarter filled → a 2×2 list.
        let diagonal: Vec<Row> = (0..4)
            .map(|i| row(&format!("m{i}.obj"), &format!("exemplar:s{i}.obj")))
            .collect();
        let l = Layout::of(&diagonal);
        assert!(!l.table);
        assert_eq!((l.lines, l.columns), (2, 2));
        assert_eq!(l.cell_of_row, [(0, 0), (0, 1), (1, 0), (1, 1)]);
    }

    #[test]
    fn labels_fit_their_band_and_statuses_their_tile() {
        let lines = label_lines("a-very-long-mesh-name-indeed", &row("m.obj", "cube"), "");
        assert!(lines[0].ends_with('…'));
        for (text, (x, y)) in lines.iter().zip(label_origins((1, 2), &lines)) {
            let (x0, y0) = tile_origin((1, 2));
            assert!(x >= x0 && x + sheet::text_width(text, TEXT_SCALE) <= x0 + TILE);
            assert!(y >= y0 + TILE && y + 7 * TEXT_SCALE <= y0 + CELL_HEIGHT);
        }
        for s in [
            "FAILED",
            "IN USE",
            "INTERRUPTED",
            "NOT RUN",
            "PARTIAL",
            "NOT DONE",
            "OTHER TASK",
            "NO RENDER",
        ] {
            assert!(sheet::text_width(s, TEXT_SCALE) <= TILE, "{s}");
        }
    }
}
