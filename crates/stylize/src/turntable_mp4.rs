//! `turntable.mp4`: the turntable's frames as an H.264 video in an MP4 file (feature `mp4`).
//!
//! **Colour.** Frame bytes are `raster_diff::image::view_bytes` of the values (the bytes the PNGs
//! and the GIF hold), taken as non-linear R'G'B' and converted with the **BT.709** matrix
//! (K_R = 0.2126, K_B = 0.0722) to **limited-range** Y'CbCr (Y' 16–235, Cb/Cr 16–240, ITU-R
//! BT.709-6 §3), rounded to nearest ([`rgb_to_ycbcr`]); chroma is subsampled 4:2:0 as the mean of
//! each 2×2 block of per-pixel Cb/Cr ([`rgb_to_yuv420`]). The SPS's VUI and the MP4's `colr`
//! (`nclx`) box both say BT.709 primaries, transfer and matrix, limited range, so players convert
//! back with the matrix the file was made with.
//!
//! **Size.** 4:2:0 needs even sides: an odd width or height is padded by one column or row
//! repeating the last one (the video is then one pixel wider or taller than the frames); a side
//! under [`MIN_SIDE`] pixels, OpenH264's smallest, is padded the same way up to it ([`video_size`]).
//! OpenH264 encodes at most 3840×2160 (or 2160×3840); larger frames are an error.
//!
//! **Encoding.** OpenH264 (Cisco's encoder, compiled from the C++ source the `openh264` crate
//! bundles), the profile OpenH264 chooses (Constrained Baseline at these sizes), one thread (the
//! bytes are then the same on every run), no frame skipping (one coded picture per frame), one IDR
//! picture first and P pictures after it, and **no rate control**: a constant quantizer, OpenH264's
//! base QP 26 (adaptive quantization moves a P picture's by a few steps), so the quality does not
//! depend on the frame size or count. On the turntable renders this decodes within 0.5–1.7 levels
//! of 255 (mean absolute difference) of the frames at 256²–48² pixels (docs/benchmarks.md,
//! "turntable.mp4"); the bunny's 36-frame 256² turntable is 47 kB (its GIF 263 kB).
//!
//! **Container.** ISO-BMFF boxes written with `mp4-atom`, the index first ("fast start", so a
//! browser plays while it downloads):
//!
//! ```text
//! ftyp  isom, minor 512, compatible isom iso2 avc1 mp41
//! moov  mvhd (timescale 1000: milliseconds; duration = frames × delay × 10)
//!       trak  tkhd (track 1, width × height)
//!             mdia  mdhd (timescale 100: one tick = 1/100 s, the GIF's unit), hdlr vide
//!                   minf  vmhd, dinf/dref/url (self-contained)
//!                         stbl  stsd/avc1 (width, height; avcC: profile, level, SPS, PPS,
//!                                          4-byte NAL lengths; colr nclx; pasp 1:1)
//!                               stts (every sample `delay` ticks), stss (the IDR samples),
//!                               stsc (one chunk of all samples), stsz, stco (the chunk's offset)
//! mdat  the samples: each frame's NAL units (SPS/PPS excluded, they are in avcC), each prefixed
//!       by its length as 4 bytes big-endian
//! ```
//!
//! The video plays once round (players loop it if asked); each frame lasts `delay` hundredths of
//! a second, as in the GIF.

use std::io::Write;
use std::path::Path;

use crate::error::{Context, IoContext, Result, invalid};
use raster_diff::Images;
use raster_diff::image::Encoding;

/// The smallest side OpenH264 encodes (its `EncodeFrame` refuses narrower or lower pictures).
pub const MIN_SIDE: usize = 16;

/// The video's width and height for frames of `width × height`: each side rounded up to even, and
/// to at least [`MIN_SIDE`] (the frame sits at the top left, its last column and row repeated).
pub fn video_size(width: usize, height: usize) -> (usize, usize) {
    let side = |n: usize| n.next_multiple_of(2).max(MIN_SIDE);
    (side(width), side(height))
}

/// The largest side OpenH264 encodes (3840×2160 or 2160×3840).
const MAX_LONG_SIDE: usize = 3840;
const MAX_SHORT_SIDE: usize = 2160;

/// The media timescale: ticks per second (one tick = 1/100 s, the GIF's delay unit).
const MEDIA_TIMESCALE: u32 = 100;
/// The movie timescale (mvhd, tkhd durations): milliseconds.
const MOVIE_TIMESCALE: u32 = 1000;

/// A picture in 8-bit Y'CbCr 4:2:0 (I420): `y` is `width × height`, `u` (Cb) and `v` (Cr) are
/// `width/2 × height/2`, rows top to bottom; `width` and `height` are even.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Yuv420 {
    /// Width in pixels (even).
    pub width: usize,
    /// Height in pixels (even).
    pub height: usize,
    /// Luma, row-major.
    pub y: Vec<u8>,
    /// Blue-difference chroma, row-major, half width and height.
    pub u: Vec<u8>,
    /// Red-difference chroma, row-major, half width and height.
    pub v: Vec<u8>,
}

/// BT.709 luma weights of R', G', B'.
const KR: f64 = 0.2126;
const KB: f64 = 0.0722;
const KG: f64 = 1.0 - KR - KB;

/// `(Y', Cb, Cr)` of one 8-bit R'G'B' pixel as real numbers (BT.709 matrix, limited range):
/// E'_Y = K_R·R' + K_G·G' + K_B·B' (R', G', B' = byte / 255),
/// Y' = 16 + 219·E'_Y, Cb = 128 + 224·(B' − E'_Y) / (2·(1 − K_B)),
/// Cr = 128 + 224·(R' − E'_Y) / (2·(1 − K_R)).
fn ycbcr_real(rgb: [u8; 3]) -> [f64; 3] {
    let [r, g, b] = rgb.map(|c| f64::from(c) / 255.0);
    let ey = KR * r + KG * g + KB * b;
    [
        16.0 + 219.0 * ey,
        128.0 + 224.0 * (b - ey) / (2.0 * (1.0 - KB)),
        128.0 + 224.0 * (r - ey) / (2.0 * (1.0 - KR)),
    ]
}

/// A real code value rounded to nearest and clamped to a byte.
fn code(v: f64) -> u8 {
    v.round().clamp(0.0, 255.0) as u8
}

/// `(Y', Cb, Cr)` of one 8-bit R'G'B' pixel, rounded (see [`ycbcr_real`]): white is
/// (235, 128, 128), black (16, 128, 128), every grey has Cb = Cr = 128.
pub fn rgb_to_ycbcr(rgb: [u8; 3]) -> [u8; 3] {
    ycbcr_real(rgb).map(code)
}

/// The R'G'B' bytes of a limited-range BT.709 `(Y', Cb, Cr)` (the inverse of [`rgb_to_ycbcr`]
/// before rounding, clamped to 0–255): what a player shows for the decoded picture.
pub fn ycbcr_to_rgb(ycbcr: [u8; 3]) -> [u8; 3] {
    let ey = (f64::from(ycbcr[0]) - 16.0) / 219.0;
    let pb = (f64::from(ycbcr[1]) - 128.0) / 224.0;
    let pr = (f64::from(ycbcr[2]) - 128.0) / 224.0;
    let r = ey + 2.0 * (1.0 - KR) * pr;
    let b = ey + 2.0 * (1.0 - KB) * pb;
    let g = (ey - KR * r - KB * b) / KG;
    [r, g, b].map(|c| code(255.0 * c))
}

/// One `width × height` frame of interleaved 8-bit R'G'B' as 4:2:0 Y'CbCr: Y' per pixel, Cb and Cr
/// the mean of each 2×2 block's real values, rounded. Odd sides are padded to even by repeating the
/// last column or row. `rgb` must hold `width × height × 3` bytes.
pub fn rgb_to_yuv420(rgb: &[u8], width: usize, height: usize) -> Result<Yuv420> {
    rgb_to_yuv420_padded(
        rgb,
        width,
        height,
        (width.next_multiple_of(2), height.next_multiple_of(2)),
    )
}

/// [`rgb_to_yuv420`] padded to `(w, h)` (even, at least the frame's), repeating the last column
/// and row.
fn rgb_to_yuv420_padded(
    rgb: &[u8],
    width: usize,
    height: usize,
    (w, h): (usize, usize),
) -> Result<Yuv420> {
    if width == 0 || height == 0 || rgb.len() != width * height * 3 {
        invalid!(
            "a {width}×{height} RGB frame needs {} bytes, got {}",
            width * height * 3,
            rgb.len()
        );
    }
    if w % 2 != 0 || h % 2 != 0 || w < width || h < height {
        invalid!("cannot pad a {width}×{height} frame to {w}×{h}");
    }
    let pixel = |x: usize, y: usize| -> [u8; 3] {
        let i = (y.min(height - 1) * width + x.min(width - 1)) * 3;
        [rgb[i], rgb[i + 1], rgb[i + 2]]
    };
    let mut out = Yuv420 {
        width: w,
        height: h,
        y: Vec::with_capacity(w * h),
        u: Vec::with_capacity(w * h / 4),
        v: Vec::with_capacity(w * h / 4),
    };
    for y in 0..h {
        for x in 0..w {
            out.y.push(code(ycbcr_real(pixel(x, y))[0]));
        }
    }
    for cy in 0..h / 2 {
        for cx in 0..w / 2 {
            let (mut cb, mut cr) = (0.0, 0.0);
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let [_, b, r] = ycbcr_real(pixel(2 * cx + dx, 2 * cy + dy));
                cb += b;
                cr += r;
            }
            out.u.push(code(cb / 4.0));
            out.v.push(code(cr / 4.0));
        }
    }
    Ok(out)
}

/// What [`encode_mp4`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Mp4Summary {
    /// Frames (samples) in the video.
    pub frames: usize,
    /// The video's width and height ([`video_size`] of the frames').
    pub width: usize,
    /// See `width`.
    pub height: usize,
    /// Bytes of the file.
    pub bytes: usize,
}

/// NAL unit type (H.264 §7.4.1: the low 5 bits of its first byte).
fn nal_type(nal: &[u8]) -> u8 {
    nal.first().map_or(0, |b| b & 0x1f)
}

/// The NAL units of an Annex B byte stream (each after a `00 00 01` or `00 00 00 01` start code),
/// without their start codes.
fn annex_b_units(stream: &[u8]) -> Vec<&[u8]> {
    let mut starts = Vec::new();
    let mut i = 0;
    while i + 3 <= stream.len() {
        if stream[i] == 0 && stream[i + 1] == 0 && stream[i + 2] == 1 {
            starts.push(i + 3);
            i += 3;
        } else {
            i += 1;
        }
    }
    let mut units = Vec::with_capacity(starts.len());
    for (k, &s) in starts.iter().enumerate() {
        let mut end = starts.get(k + 1).map_or(stream.len(), |&next| next - 3);
        // A 4-byte start code's leading zero (and any trailing_zero_8bits) belongs to no unit.
        while end > s && stream[end - 1] == 0 && k + 1 < starts.len() {
            end -= 1;
        }
        if end > s {
            units.push(&stream[s..end]);
        }
    }
    units
}

/// Encodes the views of `frames` as an H.264 MP4 (see the module documentation), each frame
/// shown `delay_cs` hundredths of a second, and writes it to `writer`.
pub fn encode_mp4<W: Write>(
    mut writer: W,
    frames: &Images,
    delay_cs: u16,
    encoding: Encoding,
) -> Result<Mp4Summary> {
    use openh264::encoder::{
        Encoder, EncoderConfig, FrameRate, FrameType, IntraFramePeriod, RateControlMode, VuiConfig,
    };
    if frames.count == 0 || frames.width == 0 || frames.height == 0 {
        invalid!("an MP4 needs at least one non-empty frame");
    }
    if delay_cs == 0 {
        invalid!("an MP4 frame must last at least 1/100 s");
    }
    let (w, h) = video_size(frames.width, frames.height);
    if w.max(h) > MAX_LONG_SIDE || w.min(h) > MAX_SHORT_SIDE {
        invalid!(
            "{}×{} frames are too large for the H.264 encoder (3840×2160 or 2160×3840 at most)",
            frames.width,
            frames.height
        );
    }
    let count = u32::try_from(frames.count)
        .ok()
        .filter(|c| c.checked_mul(u32::from(delay_cs)).is_some());
    let Some(count) = count else {
        invalid!("{} frames are too many for an MP4", frames.count);
    };
    let fps = 100.0 / f64::from(delay_cs);
    let config = EncoderConfig::new()
        .rate_control_mode(RateControlMode::Off)
        .max_frame_rate(FrameRate::from_hz(fps as f32))
        .skip_frames(false)
        .num_threads(1)
        .intra_frame_period(IntraFramePeriod::from_num_frames(0))
        .vui(VuiConfig::bt709());
    let mut encoder = Encoder::with_api_config(openh264::OpenH264API::from_source(), config)
        .map_err(crate::Error::external)
        .context("H.264 encoder")?;

    let (mut sps, mut pps): (Option<Vec<u8>>, Option<Vec<u8>>) = (None, None);
    let mut mdat: Vec<u8> = Vec::new();
    let mut sizes: Vec<u32> = Vec::with_capacity(frames.count);
    let mut sync: Vec<u32> = Vec::new();
    for i in 0..frames.count {
        let rgb = raster_diff::image::view_bytes(frames, i, encoding).context("MP4 frames")?;
        let yuv = rgb_to_yuv420_padded(&rgb, frames.width, frames.height, (w, h))?;
        let source = openh264::formats::YUVSlices::new(
            (&yuv.y, &yuv.u, &yuv.v),
            (yuv.width, yuv.height),
            (yuv.width, yuv.width / 2, yuv.width / 2),
        );
        let stream = encoder
            .encode(&source)
            .map_err(crate::Error::external)
            .with_context(|| format!("H.264 frame {i}"))?;
        let frame_type = stream.frame_type();
        if matches!(frame_type, FrameType::Skip | FrameType::Invalid) {
            invalid!("the H.264 encoder coded no picture for frame {i} ({frame_type:?})");
        }
        let bytes = stream.to_vec();
        let start = mdat.len();
        for nal in annex_b_units(&bytes) {
            match nal_type(nal) {
                7 => sps = Some(nal.to_vec()),
                8 => pps = Some(nal.to_vec()),
                _ => {
                    let len = u32::try_from(nal.len()).ok();
                    let Some(len) = len else {
                        invalid!("an H.264 NAL unit of frame {i} is over 4 GiB");
                    };
                    mdat.extend_from_slice(&len.to_be_bytes());
                    mdat.extend_from_slice(nal);
                }
            }
        }
        let Ok(size) = u32::try_from(mdat.len() - start) else {
            invalid!("H.264 frame {i} is over 4 GiB");
        };
        if size == 0 {
            invalid!("the H.264 encoder wrote no slice for frame {i}");
        }
        sizes.push(size);
        if frame_type == FrameType::IDR {
            sync.push(i as u32 + 1);
        }
    }
    let (Some(sps), Some(pps)) = (sps, pps) else {
        invalid!("the H.264 encoder wrote no SPS/PPS");
    };
    if sps.len() < 4 {
        invalid!("the H.264 encoder's SPS is {} bytes", sps.len());
    }
    let (Ok(w16), Ok(h16)) = (u16::try_from(w), u16::try_from(h)) else {
        invalid!("{w}×{h} does not fit an MP4 sample entry");
    };
    let media_duration = u64::from(count) * u64::from(delay_cs);
    let movie_duration = media_duration * u64::from(MOVIE_TIMESCALE / MEDIA_TIMESCALE);
    let bytes = mux(
        &MuxInput {
            sps: &sps,
            pps: &pps,
            width: w16,
            height: h16,
            sizes,
            sync,
            delay: u32::from(delay_cs),
            media_duration,
            movie_duration,
        },
        mdat,
    )?;
    writer
        .write_all(&bytes)
        .and_then(|()| writer.flush())
        .map_err(crate::Error::external)
        .context("cannot write the MP4")?;
    Ok(Mp4Summary {
        frames: frames.count,
        width: w,
        height: h,
        bytes: bytes.len(),
    })
}

/// What [`mux`] needs besides the sample bytes.
struct MuxInput<'a> {
    sps: &'a [u8],
    pps: &'a [u8],
    width: u16,
    height: u16,
    /// Bytes of each sample, in order.
    sizes: Vec<u32>,
    /// 1-based numbers of the sync (IDR) samples.
    sync: Vec<u32>,
    /// Media ticks per sample.
    delay: u32,
    media_duration: u64,
    movie_duration: u64,
}

/// The file: `ftyp`, `moov` (pointing at the one chunk), `mdat` (see the module documentation).
fn mux(input: &MuxInput<'_>, samples: Vec<u8>) -> Result<Vec<u8>> {
    use mp4_atom::{
        Avc1, Avcc, Colr, Dinf, Dref, Encode, Ftyp, Hdlr, Mdat, Mdhd, Mdia, Minf, Moov, Mvhd, Pasp,
        Stbl, Stco, Stsc, StscEntry, Stsd, Stss, Stsz, StszSamples, Stts, SttsEntry, Tkhd, Trak,
        Url, Visual, Vmhd,
    };
    let mut avcc = Avcc::new(input.sps, input.pps)
        .map_err(crate::Error::external)
        .context("MP4 avcC")?;
    avcc.length_size = 4;
    let avc1 = Avc1 {
        visual: Visual {
            data_reference_index: 1,
            width: input.width,
            height: input.height,
            compressor: "".into(),
            ..Default::default()
        },
        avcc,
        btrt: None,
        // BT.709 primaries, transfer and matrix, limited range: what the SPS's VUI says.
        colr: Some(Colr::Nclx {
            colour_primaries: 1,
            transfer_characteristics: 1,
            matrix_coefficients: 1,
            full_range_flag: false,
        }),
        pasp: Some(Pasp {
            h_spacing: 1,
            v_spacing: 1,
        }),
        taic: None,
        fiel: None,
        spatial: None,
    };
    let count = input.sizes.len() as u32;
    let mut moov = Moov {
        mvhd: Mvhd {
            timescale: MOVIE_TIMESCALE,
            duration: input.movie_duration,
            rate: 1.into(),
            volume: 1.into(),
            next_track_id: 2,
            ..Default::default()
        },
        trak: vec![Trak {
            tkhd: Tkhd {
                track_id: 1,
                duration: input.movie_duration,
                enabled: true,
                in_movie: true,
                width: input.width.into(),
                height: input.height.into(),
                ..Default::default()
            },
            mdia: Mdia {
                mdhd: Mdhd {
                    timescale: MEDIA_TIMESCALE,
                    duration: input.media_duration,
                    language: "und".into(),
                    ..Default::default()
                },
                hdlr: Hdlr {
                    handler: b"vide".into(),
                    name: "VideoHandler".into(),
                },
                minf: Minf {
                    vmhd: Some(Vmhd::default()),
                    dinf: Dinf {
                        dref: Dref {
                            entries: vec![Url::default().into()],
                        },
                    },
                    stbl: Stbl {
                        stsd: Stsd {
                            codecs: vec![avc1.into()],
                        },
                        stts: Stts {
                            entries: vec![SttsEntry {
                                sample_count: count,
                                sample_delta: input.delay,
                            }],
                        },
                        stss: Some(Stss {
                            entries: input.sync.clone(),
                        }),
                        stsc: Stsc {
                            entries: vec![StscEntry {
                                first_chunk: 1,
                                samples_per_chunk: count,
                                sample_description_index: 1,
                            }],
                        },
                        stsz: Stsz {
                            samples: StszSamples::Different {
                                sizes: input.sizes.clone(),
                            },
                        },
                        stco: Some(Stco { entries: vec![0] }),
                        ..Default::default()
                    },
                    ..Default::default()
                },
            },
            ..Default::default()
        }],
        ..Default::default()
    };
    let ftyp = Ftyp {
        major_brand: b"isom".into(),
        minor_version: 512,
        compatible_brands: vec![
            b"isom".into(),
            b"iso2".into(),
            b"avc1".into(),
            b"mp41".into(),
        ],
    };
    let mut head = Vec::new();
    ftyp.encode(&mut head)
        .map_err(crate::Error::external)
        .context("MP4 ftyp")?;
    let mut probe = Vec::new();
    moov.encode(&mut probe)
        .map_err(crate::Error::external)
        .context("MP4 moov")?;
    // The chunk starts after ftyp, moov and mdat's 8-byte header (stco's entry is 4 bytes
    // whatever its value, so moov's size does not change with it).
    let offset = head.len() + probe.len() + 8;
    let Ok(offset) = u32::try_from(offset) else {
        invalid!("the MP4 index is over 4 GiB");
    };
    if u32::try_from(samples.len() + 8).is_err() {
        invalid!("the MP4's video data is over 4 GiB");
    }
    moov.trak[0].mdia.minf.stbl.stco = Some(Stco {
        entries: vec![offset],
    });
    moov.encode(&mut head)
        .map_err(crate::Error::external)
        .context("MP4 moov")?;
    if head.len() + 8 != offset as usize {
        invalid!("the MP4 index changed size when its chunk offset was set");
    }
    Mdat { data: samples }
        .encode(&mut head)
        .map_err(crate::Error::external)
        .context("MP4 mdat")?;
    Ok(head)
}

/// Writes `turntable.mp4` (see [`encode_mp4`], bytes as `raster_diff::image::Encoding::Direct`)
/// atomically.
pub fn write_turntable_mp4(path: &Path, frames: &Images, delay_cs: u16) -> Result<Mp4Summary> {
    let mut summary = None;
    rundir::durable::replace_with(path, |tmp| {
        let file = std::fs::File::create(tmp).io_context("cannot create", tmp)?;
        summary = Some(
            encode_mp4(
                std::io::BufWriter::new(file),
                frames,
                delay_cs,
                Encoding::Direct,
            )
            .with_context(|| format!("cannot write {}", path.display()))?,
        );
        Ok::<(), crate::Error>(())
    })?;
    match summary {
        Some(s) => Ok(s),
        None => invalid!("{} was not written", path.display()),
    }
}

/// A video [`decode_mp4`] read back.
#[derive(Debug, Clone, PartialEq)]
pub struct DecodedMp4 {
    /// The sample entry's (and the decoded pictures') width.
    pub width: usize,
    /// The sample entry's (and the decoded pictures') height.
    pub height: usize,
    /// Ticks per second of the track (`mdhd`).
    pub timescale: u32,
    /// Each sample's duration in ticks (`stts`).
    pub durations: Vec<u32>,
    /// The decoded pictures as interleaved R'G'B' bytes ([`ycbcr_to_rgb`] of each pixel, chroma
    /// of its 2×2 block), `width × height × 3` each.
    pub frames: Vec<Vec<u8>>,
}

/// Reads an MP4 of the layout [`encode_mp4`] writes (one AVC track, `avc1` with `avcC`, samples
/// of length-prefixed NAL units located through `stsc`/`stco`/`stsz`) and decodes every sample
/// with OpenH264's decoder: how the tests and `stylize render`'s checks see what a player shows.
pub fn decode_mp4(bytes: &[u8]) -> Result<DecodedMp4> {
    use mp4_atom::{Any, Codec, Decode, StszSamples};
    use openh264::formats::YUVSource;
    let mut cursor = std::io::Cursor::new(bytes);
    let mut moov = None;
    while (cursor.position() as usize) < bytes.len() {
        let atom = Any::decode(&mut cursor)
            .map_err(crate::Error::external)
            .context("MP4 box")?;
        if let Any::Moov(m) = atom {
            moov = Some(m);
        }
    }
    let Some(moov) = moov else {
        invalid!("the MP4 has no moov box");
    };
    let [trak] = moov.trak.as_slice() else {
        invalid!("the MP4 has {} tracks, not one", moov.trak.len());
    };
    let stbl = &trak.mdia.minf.stbl;
    let Some(Codec::Avc1(avc1)) = stbl.stsd.codecs.first() else {
        invalid!("the MP4's track is not avc1");
    };
    let length_size = usize::from(avc1.avcc.length_size);
    if !(1..=4).contains(&length_size) {
        invalid!("avcC length size {length_size}");
    }
    let sizes: Vec<usize> = match &stbl.stsz.samples {
        StszSamples::Identical { count, size } => vec![*size as usize; *count as usize],
        StszSamples::Different { sizes } => sizes.iter().map(|&s| s as usize).collect(),
    };
    let chunks: Vec<u64> = match (&stbl.stco, &stbl.co64) {
        (Some(stco), _) => stco.entries.iter().map(|&o| u64::from(o)).collect(),
        (None, Some(co64)) => co64.entries.clone(),
        (None, None) => invalid!("the MP4's track has no chunk offsets"),
    };
    // Sample offsets: chunk k (1-based) holds the samples_per_chunk of the last stsc entry whose
    // first_chunk ≤ k.
    let mut offsets = Vec::with_capacity(sizes.len());
    let mut sample = 0;
    for (k, &chunk) in chunks.iter().enumerate() {
        let per = stbl
            .stsc
            .entries
            .iter()
            .rev()
            .find(|e| e.first_chunk as usize <= k + 1)
            .map_or(0, |e| e.samples_per_chunk as usize);
        let mut at = chunk as usize;
        for _ in 0..per {
            let Some(&size) = sizes.get(sample) else {
                break;
            };
            offsets.push(at);
            at += size;
            sample += 1;
        }
    }
    if offsets.len() != sizes.len() {
        invalid!(
            "the MP4's chunks hold {} samples, stsz lists {}",
            offsets.len(),
            sizes.len()
        );
    }
    let start_code = [0u8, 0, 0, 1];
    let mut stream = Vec::new();
    for ps in avc1
        .avcc
        .sequence_parameter_sets
        .iter()
        .chain(&avc1.avcc.picture_parameter_sets)
    {
        stream.extend_from_slice(&start_code);
        stream.extend_from_slice(ps);
    }
    let mut decoder = openh264::decoder::Decoder::new()
        .map_err(crate::Error::external)
        .context("H.264 decoder")?;
    let (width, height) = (
        usize::from(avc1.visual.width),
        usize::from(avc1.visual.height),
    );
    let mut frames = Vec::with_capacity(sizes.len());
    let to_rgb = |yuv: &dyn YUVSource| -> Result<Vec<u8>> {
        let (w, h) = yuv.dimensions();
        if (w, h) != (width, height) {
            invalid!("a decoded picture is {w}×{h}, the sample entry says {width}×{height}");
        }
        let (sy, su, sv) = yuv.strides();
        let mut rgb = Vec::with_capacity(w * h * 3);
        for y in 0..h {
            for x in 0..w {
                let px = ycbcr_to_rgb([
                    yuv.y()[y * sy + x],
                    yuv.u()[(y / 2) * su + x / 2],
                    yuv.v()[(y / 2) * sv + x / 2],
                ]);
                rgb.extend_from_slice(&px);
            }
        }
        Ok(rgb)
    };
    for (i, (&at, &size)) in offsets.iter().zip(&sizes).enumerate() {
        let Some(mut sample) = bytes.get(at..at + size) else {
            invalid!("MP4 sample {i} lies outside the file");
        };
        while !sample.is_empty() {
            if sample.len() < length_size {
                invalid!("MP4 sample {i} ends inside a NAL length");
            }
            let len = sample[..length_size]
                .iter()
                .fold(0usize, |a, &b| (a << 8) | usize::from(b));
            let Some(nal) = sample.get(length_size..length_size + len) else {
                invalid!("MP4 sample {i} ends inside a NAL unit");
            };
            stream.extend_from_slice(&start_code);
            stream.extend_from_slice(nal);
            sample = &sample[length_size + len..];
        }
        let decoded = decoder
            .decode(&stream)
            .map_err(crate::Error::external)
            .with_context(|| format!("H.264 sample {i}"))?;
        stream.clear();
        if let Some(yuv) = decoded {
            frames.push(to_rgb(&yuv)?);
        }
    }
    for yuv in decoder
        .flush_remaining()
        .map_err(crate::Error::external)
        .context("H.264 decoder flush")?
    {
        frames.push(to_rgb(&yuv)?);
    }
    let durations = stbl
        .stts
        .entries
        .iter()
        .flat_map(|e| std::iter::repeat_n(e.sample_delta, e.sample_count as usize))
        .collect();
    Ok(DecodedMp4 {
        width,
        height,
        timescale: trak.mdia.mdhd.timescale,
        durations,
        frames,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// BT.709-6's colour bars at 100 %: the limited-range code values of the primaries, the
    /// secondaries, white and black (Rec. ITU-R BT.709-6 §3.5, rounded; also EBU/SMPTE 100 % bar
    /// tables), not values read off this code.
    #[test]
    fn known_colours_have_bt709_limited_range_codes() {
        let bars: [([u8; 3], [u8; 3]); 8] = [
            ([255, 255, 255], [235, 128, 128]),
            ([255, 255, 0], [219, 16, 138]),
            ([0, 255, 255], [188, 154, 16]),
            ([0, 255, 0], [173, 42, 26]),
            ([255, 0, 255], [78, 214, 230]),
            ([255, 0, 0], [63, 102, 240]),
            ([0, 0, 255], [32, 240, 118]),
            ([0, 0, 0], [16, 128, 128]),
        ];
        for (rgb, ycbcr) in bars {
            assert_eq!(rgb_to_ycbcr(rgb), ycbcr, "{rgb:?}");
            // The inverse brings the code values back to the colour, within a level.
            let back = ycbcr_to_rgb(ycbcr);
            for c in 0..3 {
                assert!(
                    back[c].abs_diff(rgb[c]) <= 1,
                    "{rgb:?} → {ycbcr:?} → {back:?}"
                );
            }
        }
        // Every grey is achromatic; its luma is 16 + 219·v/255.
        for v in 0..=255u8 {
            let [y, cb, cr] = rgb_to_ycbcr([v, v, v]);
            assert_eq!((cb, cr), (128, 128), "grey {v}");
            assert_eq!(
                y,
                (16.0 + 219.0 * f64::from(v) / 255.0).round() as u8,
                "grey {v}"
            );
            let back = ycbcr_to_rgb([y, cb, cr]);
            assert!(
                back.iter().all(|&c| c.abs_diff(v) <= 1),
                "grey {v}: {back:?}"
            );
        }
    }

    #[test]
    fn yuv420_averages_chroma_per_block_and_pads_odd_sides() {
        // 3×1: red, blue, green → padded to 4×2 (the green column and the row repeated).
        let rgb = [255, 0, 0, 0, 0, 255, 0, 255, 0];
        let yuv = rgb_to_yuv420(&rgb, 3, 1).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((yuv.width, yuv.height), (4, 2));
        assert_eq!(yuv.y, [63, 32, 173, 173, 63, 32, 173, 173]);
        // Block 0: red and blue twice each → the mean of their real Cb and Cr.
        let mean =
            |a: [u8; 3], b: [u8; 3], k: usize| code((ycbcr_real(a)[k] + ycbcr_real(b)[k]) / 2.0);
        let (red, blue, green) = ([255, 0, 0], [0, 0, 255], [0, 255, 0]);
        assert_eq!(yuv.u, [mean(red, blue, 1), rgb_to_ycbcr(green)[1]]);
        assert_eq!(yuv.v, [mean(red, blue, 2), rgb_to_ycbcr(green)[2]]);
        assert!(rgb_to_yuv420(&rgb, 2, 2).is_err());
        assert!(rgb_to_yuv420(&[], 0, 1).is_err());
    }

    #[test]
    fn annex_b_units_split_on_3_and_4_byte_start_codes() {
        let stream = [
            0, 0, 0, 1, 0x67, 1, 2, 0, 0, 1, 0x68, 3, 0, 0, 0, 1, 0x65, 4, 5, 0,
        ];
        let units = annex_b_units(&stream);
        assert_eq!(
            units,
            [&[0x67, 1, 2][..], &[0x68, 3][..], &[0x65, 4, 5, 0][..]]
        );
        assert_eq!(
            units.iter().map(|u| nal_type(u)).collect::<Vec<_>>(),
            [7, 8, 5]
        );
    }

    /// Frames of a tetrahedron turning (the run's turntable renderer), `n` views of `size`².
    fn tetrahedron_frames(n: usize, size: usize) -> Images {
        let positions = [
            [0.0, 0.9, 0.0],
            [-0.8, -0.4, 0.5],
            [0.8, -0.4, 0.5],
            [0.0, -0.4, -0.9],
        ];
        let faces = [[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]];
        crate::run_pictures::filled_orbit(&positions, &faces, n, size, 60.0, None)
            .unwrap_or_else(|e| panic!("{e:#}"))
    }

    /// The GIF's frames (RGBA decoded, alpha dropped).
    fn gif_frames(frames: &Images) -> Vec<Vec<u8>> {
        let mut bytes = Vec::new();
        crate::run_pictures::encode_gif(&mut bytes, frames, 8, Encoding::Direct)
            .unwrap_or_else(|e| panic!("{e:#}"));
        let mut options = gif::DecodeOptions::new();
        options.set_color_output(gif::ColorOutput::RGBA);
        let mut decoder = options
            .read_info(std::io::Cursor::new(bytes))
            .unwrap_or_else(|e| panic!("{e}"));
        let mut out = Vec::new();
        while let Some(f) = decoder.read_next_frame().unwrap_or_else(|e| panic!("{e}")) {
            out.push(
                f.buffer
                    .chunks_exact(4)
                    .flat_map(|p| [p[0], p[1], p[2]])
                    .collect(),
            );
        }
        out
    }

    /// Mean absolute difference of two R'G'B' pictures over the `w × h` window they share (rows of
    /// `wa` and `wb` pixels).
    fn mean_abs_difference(a: &[u8], wa: usize, b: &[u8], wb: usize, w: usize, h: usize) -> f64 {
        let mut sum = 0u64;
        for y in 0..h {
            for x in 0..w * 3 {
                sum += u64::from(a[y * wa * 3 + x].abs_diff(b[y * wb * 3 + x]));
            }
        }
        sum as f64 / (w * h * 3) as f64
    }

    /// The decoded video against the GIF of the same frames. Bound: a mean absolute difference of
    /// at most 4 levels of 255 per channel (1.6 %). The colour round trip alone is within one
    /// level (`known_colours…`); what remains is H.264's quantization at QP ≤ 30 of smooth
    /// shading. The bound is what "resembles" means here, chosen before measuring; the check
    /// against the *next* view shows that a swapped or repeated frame misses it by far.
    #[test]
    fn mp4_decodes_to_the_gifs_frames_with_their_count_size_and_timing() {
        let frames = tetrahedron_frames(6, 48);
        let mut bytes = Vec::new();
        let summary = encode_mp4(&mut bytes, &frames, 8, Encoding::Direct)
            .unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!((summary.frames, summary.width, summary.height), (6, 48, 48));
        assert_eq!(summary.bytes, bytes.len());
        assert_eq!(&bytes[4..8], b"ftyp");
        let video = decode_mp4(&bytes).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!((video.width, video.height), (48, 48));
        assert_eq!(video.frames.len(), 6);
        assert_eq!(video.timescale, 100);
        assert_eq!(video.durations, [8; 6]);
        let gif = gif_frames(&frames);
        assert_eq!(gif.len(), 6);
        for (k, mp4) in video.frames.iter().enumerate() {
            let d = mean_abs_difference(mp4, 48, &gif[k], 48, 48, 48);
            assert!(d <= 4.0, "frame {k}: mean |mp4 − gif| = {d:.2} levels");
            let other = mean_abs_difference(mp4, 48, &gif[(k + 1) % 6], 48, 48, 48);
            assert!(other > 4.0, "frame {k} against the next view: {other:.2}");
        }
        // The same frames give the same bytes (one encoder thread): a resumed run's file equals an
        // uninterrupted one's.
        let mut again = Vec::new();
        encode_mp4(&mut again, &frames, 8, Encoding::Direct).unwrap_or_else(|e| panic!("{e:#}"));
        assert!(
            again == bytes,
            "the MP4 differs between two encodings of the same frames"
        );
    }

    /// The fidelity table of docs/benchmarks.md ("turntable.mp4"): worst mean absolute difference
    /// against the GIF and bytes, 6 frames at 48², 128², 256². A measurement, not a check:
    /// `cargo test -p stylize --lib turntable_mp4::tests::fidelity_survey -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn fidelity_survey() {
        for size in [48, 128, 256] {
            let frames = tetrahedron_frames(6, size);
            let gif = gif_frames(&frames);
            let mut bytes = Vec::new();
            encode_mp4(&mut bytes, &frames, 8, Encoding::Direct)
                .unwrap_or_else(|e| panic!("{e:#}"));
            let video = decode_mp4(&bytes).unwrap_or_else(|e| panic!("{e:#}"));
            let worst = video
                .frames
                .iter()
                .zip(&gif)
                .map(|(m, g)| mean_abs_difference(m, size, g, size, size, size))
                .fold(0.0, f64::max);
            println!(
                "{size}²: worst mean |mp4 − gif| {worst:.2} levels, {} bytes",
                bytes.len()
            );
        }
    }

    #[test]
    fn odd_frames_are_padded_to_even_and_decode_to_the_frame_inside() {
        // 25×25 frames (the render's square tiles at an odd --size) → a 26×26 video.
        let frames = tetrahedron_frames(2, 25);
        let mut bytes = Vec::new();
        let summary = encode_mp4(&mut bytes, &frames, 5, Encoding::Direct)
            .unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!((summary.width, summary.height), (26, 26));
        let video = decode_mp4(&bytes).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!((video.width, video.height, video.frames.len()), (26, 26, 2));
        assert_eq!(video.durations, [5, 5]);
        for (k, (mp4, gif)) in video.frames.iter().zip(gif_frames(&frames)).enumerate() {
            let d = mean_abs_difference(mp4, 26, &gif, 25, 25, 25);
            assert!(d <= 4.0, "frame {k}: {d:.2}");
        }
    }

    #[test]
    fn unencodable_frames_are_errors_not_panics() {
        let empty = Images {
            count: 0,
            height: 8,
            width: 8,
            channels: 3,
            rgb: Vec::new(),
        };
        assert!(encode_mp4(Vec::new(), &empty, 8, Encoding::Direct).is_err());
        let frames = tetrahedron_frames(1, 8);
        assert!(encode_mp4(Vec::new(), &frames, 0, Encoding::Direct).is_err());
        // Below OpenH264's 16 pixels: padded up to them, not refused.
        assert_eq!(video_size(8, 3), (16, 16));
        assert_eq!(video_size(17, 40), (18, 40));
        let mut bytes = Vec::new();
        let s = encode_mp4(&mut bytes, &frames, 8, Encoding::Direct)
            .unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!((s.width, s.height), (16, 16));
        let video = decode_mp4(&bytes).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!((video.width, video.height, video.frames.len()), (16, 16, 1));
        let huge = Images {
            count: 1,
            height: 4000,
            width: 4000,
            channels: 3,
            rgb: Vec::new(),
        };
        let e = encode_mp4(Vec::new(), &huge, 8, Encoding::Direct).expect_err("too large");
        assert!(e.to_string().contains("3840"), "{e}");
        assert!(decode_mp4(b"not an mp4").is_err());
    }
}
