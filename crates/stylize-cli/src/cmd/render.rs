//! `stylize render`: turntable frames, a contact sheet, an animated `turntable.gif` and an H.264
//! `turntable.mp4` of a mesh.
//!
//! The mesh is read with `mesh_core::io::read_mesh`, normalized to the side-2 cube (spec §1.1) and
//! rendered with the project's renderer (`raster_diff`, the shading the guidance sees) from
//! `--turntable N` cameras on a circle (azimuth 360°·k/N, fixed elevation and distance, light at the
//! camera). Pixel values are written as they are, byte = round(255·v) (see `raster_diff::image`);
//! `--srgb` applies the sRGB transfer curve first. `turntable.gif` loops over the same frames
//! (`stylize::run_pictures::encode_gif`: exact greys, colour frames quantized); `--no-gif` skips it.
//! `turntable.mp4` holds the same frames as H.264 (`stylize::turntable_mp4`: BT.709 limited range,
//! 4:2:0, an odd `--size` padded to even, one under 16 to 16; the library's feature `mp4`); `--no-mp4` skips it. A
//! build without the encoder says so and writes the rest; an encoding failure is reported after
//! every other output is written (the command then fails).

use std::path::{Path, PathBuf};

use anyhow::Context;
use raster_diff::image::{Encoding, contact_sheet, write_png};
use raster_diff::{Backend, Images, orbit_views, select_renderer};

/// Pixels rendered per batch (8 views of 1024²; at least one view): bounds the renderer's
/// per-render memory.
const BATCH_PIXELS: usize = 8 * 1024 * 1024;
/// The most frames (`--turntable`).
const MAX_FRAMES: usize = 360;
/// The largest `--size`.
const MAX_SIZE: usize = 8192;
/// The largest `--size` the H.264 encoder takes (OpenH264: 3840×2160 at most, so square frames
/// of at most 2160, after rounding up to even).
const MAX_MP4_SIZE: usize = 2160;
/// The most pixels of all frames together (kept for the contact sheet and the GIF, 12 bytes
/// each): 2²⁷, e.g. 8 frames of 4096², 36 of 1930², 360 of 610².
const MAX_TOTAL_PIXELS: usize = 1 << 27;

/// Arguments of `stylize render`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Mesh file (OBJ, OFF, PLY, glTF/GLB).
    pub mesh: PathBuf,
    /// Number of turntable frames (1 to 360).
    #[arg(long, default_value_t = 8, allow_negative_numbers = true)]
    pub turntable: usize,
    /// Output folder (created if missing).
    #[arg(short, long = "out", alias = "output", value_name = "DIR")]
    pub output: PathBuf,
    /// Image width and height in pixels (1 to 8192; frames × size² at most 2²⁷).
    #[arg(long, default_value_t = 512, allow_negative_numbers = true)]
    pub size: usize,
    /// Camera elevation in degrees.
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    pub elevation: f64,
    /// Camera distance from the origin (the mesh fills the side-2 cube).
    #[arg(long, default_value_t = 2.5, allow_negative_numbers = true)]
    pub distance: f64,
    /// Vertical field of view in degrees (90° is the reference's effective value).
    #[arg(long, default_value_t = 90.0, allow_negative_numbers = true)]
    pub fov: f64,
    /// Columns of the contact sheet (default: ceil(sqrt(N))).
    #[arg(long)]
    pub columns: Option<usize>,
    /// Apply the sRGB transfer curve to the values before 8-bit quantization.
    #[arg(long)]
    pub srgb: bool,
    /// Use the CPU renderer even if a GPU backend is available.
    #[arg(long)]
    pub cpu: bool,
    /// Do not write the animated `turntable.gif`.
    #[arg(long)]
    pub no_gif: bool,
    /// Do not write the H.264 video `turntable.mp4`.
    #[arg(long)]
    pub no_mp4: bool,
    /// Overwrite existing frames, contact sheet, GIF and MP4 (and remove the frames, or the GIF
    /// with `--no-gif`, the MP4 with `--no-mp4`, that an earlier render left beyond this one's).
    #[arg(long)]
    pub force: bool,
}

fn frame_path(dir: &Path, k: usize) -> PathBuf {
    dir.join(format!("frame_{k:03}.png"))
}

/// The frame number of a `frame_NNN.png` name (digits, at least three).
fn frame_number(name: &str) -> Option<usize> {
    let digits = name.strip_prefix("frame_")?.strip_suffix(".png")?;
    (digits.len() >= 3 && digits.bytes().all(|b| b.is_ascii_digit()))
        .then(|| digits.parse().ok())
        .flatten()
}

/// The frames `frame_NNN.png` in `dir` numbered `frames` or more: an earlier, longer render's.
fn stale_frames(dir: &Path, frames: usize) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut stale: Vec<PathBuf> = entries
        .flatten()
        .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
        .filter(|e| frame_number(&e.file_name().to_string_lossy()).is_some_and(|k| k >= frames))
        .map(|e| e.path())
        .collect();
    stale.sort();
    stale
}

fn save(path: &Path, images: &Images, index: usize, encoding: Encoding) -> anyhow::Result<()> {
    rundir::durable::replace_with(path, |tmp| {
        let file =
            std::fs::File::create(tmp).map_err(|e| stylize::Error::io("cannot create", tmp, e))?;
        write_png(std::io::BufWriter::new(file), images, index, encoding)
            .map_err(stylize::Error::from)
    })
    .with_context(|| format!("writing {}", path.display()))
}

/// Runs `stylize render`.
pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(
        (1..=MAX_FRAMES).contains(&args.turntable),
        "--turntable must be in 1..={MAX_FRAMES}, got {}",
        args.turntable
    );
    anyhow::ensure!(
        (1..=MAX_SIZE).contains(&args.size),
        "--size must be in 1..={MAX_SIZE}, got {}",
        args.size
    );
    anyhow::ensure!(
        args.turntable * args.size * args.size <= MAX_TOTAL_PIXELS,
        "--turntable {} at --size {} is {} pixels in all, more than the {MAX_TOTAL_PIXELS} \
         (2^27) a render keeps in memory for its contact sheet and GIF: fewer frames or a \
         smaller --size",
        args.turntable,
        args.size,
        args.turntable * args.size * args.size
    );
    if let Some(c) = args.columns {
        anyhow::ensure!(c >= 1, "--columns must be at least 1");
    }
    anyhow::ensure!(
        args.no_mp4 || !MP4_BUILT || args.size <= MAX_MP4_SIZE,
        "--size {} is larger than the {MAX_MP4_SIZE} the H.264 encoder takes for turntable.mp4: \
         a smaller --size, or --no-mp4",
        args.size
    );
    anyhow::ensure!(
        args.distance.is_finite() && args.distance > 0.0,
        "--distance must be positive, got {}",
        args.distance
    );
    anyhow::ensure!(
        args.fov > 0.0 && args.fov < 180.0,
        "--fov must be between 0 and 180 degrees, got {}",
        args.fov
    );
    let mut mesh = mesh_core::io::read_mesh(&args.mesh)
        .with_context(|| format!("reading mesh {}", args.mesh.display()))?;
    mesh_core::normalize::side2_cube(&mut mesh.positions);

    let dir = &args.output;
    let sheet_path = dir.join("contact_sheet.png");
    let gif_path = dir.join("turntable.gif");
    let mp4_path = dir.join("turntable.mp4");
    let write_mp4 = !args.no_mp4 && MP4_BUILT;
    let outputs: Vec<PathBuf> = (0..args.turntable)
        .map(|k| frame_path(dir, k))
        .chain([sheet_path.clone()])
        .chain((!args.no_gif).then(|| gif_path.clone()))
        .chain(write_mp4.then(|| mp4_path.clone()))
        .collect();
    rundir::refuse_overwriting_inputs(
        &outputs,
        &[],
        &[("input mesh".to_string(), args.mesh.clone())],
    )?;
    if !args.force {
        let existing = outputs.iter().find(|p| p.exists());
        if let Some(p) = existing {
            anyhow::bail!("{} already exists (use --force to overwrite)", p.display());
        }
    }
    std::fs::create_dir_all(dir)
        .with_context(|| format!("creating output folder {}", dir.display()))?;

    let backend = if args.cpu {
        Backend::Cpu
    } else {
        Backend::Auto
    };
    let (mut renderer, why) = select_renderer(backend)?;
    errln!("renderer: {why}");
    let views = orbit_views(args.turntable, args.elevation, args.distance, args.fov);
    let encoding = if args.srgb {
        Encoding::SrgbFromLinear
    } else {
        Encoding::Direct
    };
    let mut all = Images {
        count: 0,
        height: args.size,
        width: args.size,
        channels: 3,
        rgb: Vec::new(),
    };
    let batch = (BATCH_PIXELS / (args.size * args.size)).max(1);
    for (b, chunk) in views.chunks(batch).enumerate() {
        // RGB whichever backend rendered them (the CPU one renders grey): the sheet and the GIF
        // are RGB.
        let images = renderer
            .render(&mesh.positions, &mesh.faces, chunk, args.size, args.size)
            .map(Images::into_rgb)
            .with_context(|| format!("rendering {}", args.mesh.display()))?;
        for i in 0..images.count {
            save(&frame_path(dir, b * batch + i), &images, i, encoding)?;
        }
        all.count += images.count;
        all.rgb.extend_from_slice(&images.rgb);
    }
    let columns = args
        .columns
        .unwrap_or_else(|| (args.turntable as f64).sqrt().ceil() as usize);
    save(&sheet_path, &contact_sheet(&all, columns), 0, encoding)?;
    if !args.no_gif {
        rundir::durable::replace_with(&gif_path, |tmp| {
            let file = std::fs::File::create(tmp)
                .map_err(|e| stylize::Error::io("cannot create", tmp, e))?;
            stylize::run_pictures::encode_gif(
                std::io::BufWriter::new(file),
                &all,
                stylize::run_pictures::GIF_FRAME_DELAY_CS,
                encoding,
            )
        })
        .with_context(|| format!("cannot write {}", gif_path.display()))?;
    }
    let mp4 = if write_mp4 {
        Some(write_turntable_mp4(&mp4_path, &all, encoding))
    } else {
        if !args.no_mp4 {
            errln!(
                "turntable.mp4 not written: this stylize was built without the H.264 encoder \
                 (feature mp4; {} builds it)",
                crate::features::cargo_run_adding("mp4")
            );
        }
        None
    };
    if args.force {
        // What an earlier render left beyond this one's outputs would pass for part of them.
        let mut stale = stale_frames(dir, args.turntable);
        if args.no_gif && gif_path.is_file() {
            stale.push(gif_path.clone());
        }
        if !write_mp4 && mp4_path.is_file() {
            stale.push(mp4_path.clone());
        }
        for p in &stale {
            std::fs::remove_file(p).with_context(|| format!("cannot remove {}", p.display()))?;
        }
        if !stale.is_empty() {
            errln!(
                "removed {} file(s) left by an earlier render ({} …)",
                stale.len(),
                stale[0].display()
            );
        }
    }
    let mut written = vec!["contact_sheet.png"];
    if !args.no_gif {
        written.push("turntable.gif");
    }
    if matches!(mp4, Some(Ok(()))) {
        written.push("turntable.mp4");
    }
    errln!(
        "wrote {} frames, {} to {}",
        args.turntable,
        written.join(", "),
        dir.display()
    );
    match mp4 {
        Some(Err(e)) => Err(e.context(format!(
            "the frames, contact sheet{} were written, but not {}",
            if args.no_gif { "" } else { " and GIF" },
            mp4_path.display()
        ))),
        _ => Ok(()),
    }
}

/// Whether this build has the H.264 encoder (`stylize`'s feature `mp4`, through this crate's).
const MP4_BUILT: bool = cfg!(feature = "mp4");

/// Writes `turntable.mp4` of the frames; an existing file is replaced only when the new one is
/// complete, and a failure leaves no partial file.
#[cfg(feature = "mp4")]
fn write_turntable_mp4(path: &Path, frames: &Images, encoding: Encoding) -> anyhow::Result<()> {
    rundir::durable::replace_with(path, |tmp| {
        let file =
            std::fs::File::create(tmp).map_err(|e| stylize::Error::io("cannot create", tmp, e))?;
        stylize::turntable_mp4::encode_mp4(
            std::io::BufWriter::new(file),
            frames,
            stylize::run_pictures::GIF_FRAME_DELAY_CS,
            encoding,
        )
        .map(|_| ())
    })
    .with_context(|| format!("cannot write {}", path.display()))
}

#[cfg(not(feature = "mp4"))]
fn write_turntable_mp4(_: &Path, _: &Images, _: Encoding) -> anyhow::Result<()> {
    Err(crate::features::not_built("mp4", "turntable.mp4"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(mesh: PathBuf, output: PathBuf, force: bool) -> Args {
        Args {
            mesh,
            turntable: 3,
            output,
            size: 24,
            elevation: 20.0,
            distance: 2.5,
            fov: 90.0,
            columns: None,
            srgb: false,
            cpu: true,
            no_gif: false,
            no_mp4: false,
            force,
        }
    }

    /// A tetrahedron written to `dir/tet.obj`.
    fn tetrahedron(dir: &Path) -> PathBuf {
        let mesh = dir.join("tet.obj");
        std::fs::write(
            &mesh,
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
        )
        .expect("write obj");
        mesh
    }

    /// Width and height from the PNG signature and IHDR chunk (bytes 16..24, big-endian).
    fn png_size(path: &Path) -> (u32, u32) {
        let bytes = std::fs::read(path).expect("png exists");
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        assert_eq!(&bytes[12..16], b"IHDR");
        let be =
            |i: usize| u32::from_be_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
        (be(16), be(20))
    }

    #[test]
    fn writes_frames_and_contact_sheet_and_refuses_to_overwrite_without_force() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let mesh = tetrahedron(tmp.path());
        let out = tmp.path().join("renders/nested");
        run(args(mesh.clone(), out.clone(), false)).expect("first render");
        for k in 0..3 {
            assert_eq!(png_size(&frame_path(&out, k)), (24, 24));
        }
        // 3 frames, ceil(sqrt 3) = 2 columns → 2×2 grid.
        assert_eq!(png_size(&out.join("contact_sheet.png")), (48, 48));
        // The GIF loops over the same 3 frames.
        let gif = std::fs::read(out.join("turntable.gif")).expect("turntable.gif");
        let mut decoder = gif::DecodeOptions::new()
            .read_info(std::io::Cursor::new(gif))
            .expect("the GIF decodes");
        assert_eq!((decoder.width(), decoder.height()), (24, 24));
        let mut frames = 0;
        while decoder.read_next_frame().expect("frame").is_some() {
            frames += 1;
        }
        assert_eq!(frames, 3);
        // So does the MP4: 3 pictures of 24×24, 8/100 s each.
        #[cfg(feature = "mp4")]
        {
            let mp4 = std::fs::read(out.join("turntable.mp4")).expect("turntable.mp4");
            let video = stylize::turntable_mp4::decode_mp4(&mp4).expect("the MP4 decodes");
            assert_eq!((video.width, video.height, video.frames.len()), (24, 24, 3));
            assert_eq!(video.durations, [8, 8, 8]);
        }
        // A GIF left from an earlier render blocks a render without --force, like the frames.
        std::fs::remove_file(out.join("contact_sheet.png")).expect("rm");
        for k in 0..3 {
            std::fs::remove_file(frame_path(&out, k)).expect("rm");
        }
        assert!(run(args(mesh.clone(), out.clone(), false)).is_err());
        assert!(run(args(mesh.clone(), out.clone(), false)).is_err());
        run(args(mesh, out, true)).expect("forced render");
    }

    #[test]
    fn forced_shorter_render_removes_the_earlier_frames_beyond_it() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let mesh = tetrahedron(tmp.path());
        let out = tmp.path().join("r");
        let mut a = args(mesh.clone(), out.clone(), false);
        a.turntable = 5;
        run(a).expect("first render");
        std::fs::write(out.join("frame_notes.png"), "mine").expect("write");
        let mut a = args(mesh, out.clone(), true);
        a.turntable = 2;
        a.no_gif = true;
        a.no_mp4 = true;
        run(a).expect("forced render");
        let mut names: Vec<String> = std::fs::read_dir(&out)
            .expect("dir")
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(
            names,
            [
                "contact_sheet.png",
                "frame_000.png",
                "frame_001.png",
                "frame_notes.png"
            ]
        );
    }

    #[test]
    fn out_of_range_options_are_rejected_before_anything_is_written() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let out = tmp.path().join("out");
        let base = || args(tmp.path().join("nope.obj"), out.clone(), false);
        type Edit = fn(&mut Args);
        let cases: [(&str, Edit); 5] = [
            ("--turntable", |a| a.turntable = 0),
            ("--turntable", |a| a.turntable = 100_000),
            ("--size", |a| a.size = 9000),
            ("2^27", |a| (a.turntable, a.size) = (360, 2048)),
            ("--columns", |a| a.columns = Some(0)),
        ];
        for (needle, edit) in cases {
            let mut a = base();
            edit(&mut a);
            let e = format!("{:#}", run(a).expect_err("rejected"));
            assert!(e.contains(needle), "{needle}: {e}");
        }
        if MP4_BUILT {
            // Frames the H.264 encoder cannot take are refused before rendering, naming the way out.
            let mut a = base();
            a.size = 2162;
            let e = format!("{:#}", run(a).expect_err("rejected"));
            assert!(e.contains("--no-mp4"), "{e}");
        }
        assert!(!out.exists());
        assert_eq!(frame_number("frame_012.png"), Some(12));
        assert_eq!(frame_number("frame_1234.png"), Some(1234));
        for n in [
            "frame_01.png",
            "frame_abc.png",
            "frame_001.jpg",
            "xframe_001.png",
        ] {
            assert_eq!(frame_number(n), None, "{n}");
        }
    }

    #[test]
    fn missing_mesh_is_an_error_not_a_panic() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let err = run(args(
            tmp.path().join("nope.obj"),
            tmp.path().join("out"),
            false,
        ))
        .expect_err("must fail");
        assert!(format!("{err:#}").contains("nope.obj"));
    }
}
