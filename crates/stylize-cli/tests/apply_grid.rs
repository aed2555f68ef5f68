//! `stylize apply --lambda 5,8,11` writes the labelled comparison sheet `OUT_grid.png`: its size,
//! each tile (column = λ, row = view) against a render of the mesh written for that λ, and each
//! label's ink at its position under its column.

use std::path::{Path, PathBuf};

use stylize_cli::cmd::apply::{Args, LambdaArg, run};
use stylize_cli::cmd::apply_grid::{
    GRID_VIEWS, LABEL_HEIGHT, TILE, grid_path, label_mask, label_origin, label_text, tiles,
};

mod common;
use common::ok;

fn golden(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/golden")
        .join(name)
}

/// (width, height, RGB8 pixels) of a PNG.
fn read_png(path: &Path) -> (usize, usize, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(ok(std::fs::File::open(path))));
    let mut reader = ok(decoder.read_info());
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = ok(reader.next_frame(&mut buf));
    assert_eq!(info.color_type, png::ColorType::Rgb, "an RGB sheet");
    buf.truncate(info.buffer_size());
    (info.width as usize, info.height as usize, buf)
}

#[test]
fn several_lambdas_write_a_labelled_sheet_of_their_results() {
    let dir = ok(tempfile::tempdir());
    let out = dir.path().join("bunny.obj");
    let lambdas = [5.0, 8.0, 11.0];
    ok(run(Args {
        saved: golden("bunny_targets.npz"),
        output: out.clone(),
        lambda: lambdas.iter().map(|&l| LambdaArg::Value(l)).collect(),
        strength: vec![],
        rotation_rule: None,
        mask: None,
        region: vec![],
        region_feather: None,
        no_region: false,
        force: false,
        output_frame: None,
    }));
    let sheet = ok(grid_path(&out));
    assert_eq!(sheet, dir.path().join("bunny_grid.png"));
    let (w, h, px) = read_png(&sheet);
    assert_eq!((w, h), (3 * TILE, GRID_VIEWS * TILE + LABEL_HEIGHT));
    let at = |x: usize, y: usize| &px[(y * w + x) * 3..(y * w + x) * 3 + 3];
    for (j, lambda) in lambdas.iter().enumerate() {
        // Tiles: the views of the mesh written for this λ, rendered again here.
        let mesh = ok(mesh_core::io::read_mesh(
            dir.path().join(format!("bunny_lambda{lambda}.obj")),
        ));
        let expected = ok(tiles(&mesh.positions, &mesh.faces));
        for v in 0..GRID_VIEWS {
            let view = expected.view(v);
            let mut differing = 0;
            for y in 0..TILE {
                for x in 0..TILE {
                    let want = &view[(y * TILE + x) * 3..(y * TILE + x) * 3 + 3];
                    let got = at(j * TILE + x, v * TILE + y);
                    let close = (0..3).all(|c| {
                        (f32::from(got[c]) - (want[c].clamp(0.0, 1.0) * 255.0).round()).abs() <= 1.0
                    });
                    differing += usize::from(!close);
                }
            }
            assert_eq!(differing, 0, "column λ = {lambda}, view {v}");
        }
        // The label: black exactly where its glyphs are, white elsewhere in the column's strip.
        let text = label_text(*lambda);
        let (lw, lh, mask) = label_mask(&text);
        let (x0, y0) = label_origin(j, &text);
        assert!(
            x0 >= j * TILE && x0 + lw <= (j + 1) * TILE,
            "label under its column"
        );
        for y in GRID_VIEWS * TILE..h {
            for x in j * TILE..(j + 1) * TILE {
                let inside = (x0..x0 + lw).contains(&x) && (y0..y0 + lh).contains(&y);
                let ink = inside && mask[(y - y0) * lw + (x - x0)];
                let want: &[u8] = if ink { &[0, 0, 0] } else { &[255, 255, 255] };
                assert_eq!(at(x, y), want, "{text} at ({x}, {y})");
            }
        }
    }
    // The labels differ (λ=5, λ=8, λ=11), so a sheet with columns swapped would fail above.
    assert_ne!(
        label_mask(&label_text(5.0)).2,
        label_mask(&label_text(8.0)).2
    );
}
