//! NumPy arrays on disk: the `.npy` format (this module) and, with the default feature `npz`, the
//! `.npz` archive ([`npz`]). Nothing here knows about meshes; mesh-core, diffusion-onnx and stylize
//! build their files on it.
//!
//! The `.npy` array format (NumPy format versions 1.0, 2.0 and 3.0), little-endian, C order.
//!
//! Layout: magic `\x93NUMPY`, two version bytes, a header length (`u16` LE in 1.0, `u32` LE in 2.0
//! and 3.0), then an ASCII (UTF-8 in 3.0) Python dict literal
//! `{'descr': '<f4', 'fortran_order': False, 'shape': (V, 3), }` padded with spaces and ending in
//! `\n` so that the data starts at a multiple of 64 bytes, then the raw elements in C (row-major)
//! order. Supported `descr`: `<f2 <f4 <f8 <i8 <i4 <u4 |u1 |b1 <U{n}`; `<U{n}` stores each element as
//! `n` UTF-32LE code units, padded with NUL at the end; `<f2` is IEEE half precision (DeepFloyd IF
//! ships its empty-prompt embedding in it).
//!
//! [`parse_npy`] and [`write_npy`] work on bytes and need no zip support; [`npz`] (feature `npz`,
//! on by default, the only user of the `zip` dependency) builds `.npz` archives on them.

mod error;
#[cfg(feature = "npz")]
pub mod npz;

pub use error::{NpyError, ensure_regular_file};

/// The elements of an array, by dtype.
#[derive(Clone, Debug, PartialEq)]
pub enum NpyData {
    /// `<f2` (IEEE half).
    F16(Vec<half::f16>),
    /// `<f4`.
    F32(Vec<f32>),
    /// `<f8`.
    F64(Vec<f64>),
    /// `<i8`.
    I64(Vec<i64>),
    /// `<i4`.
    I32(Vec<i32>),
    /// `<u4`.
    U32(Vec<u32>),
    /// `|u1`.
    U8(Vec<u8>),
    /// `|b1` (one byte per element, 0 or 1).
    Bool(Vec<bool>),
    /// `<U{n}`: fixed-width unicode strings (trailing NULs stripped on read, as NumPy does).
    Unicode(Vec<String>),
}

impl NpyData {
    /// Number of elements.
    pub fn len(&self) -> usize {
        match self {
            NpyData::F16(v) => v.len(),
            NpyData::F32(v) => v.len(),
            NpyData::F64(v) => v.len(),
            NpyData::I64(v) => v.len(),
            NpyData::I32(v) => v.len(),
            NpyData::U32(v) => v.len(),
            NpyData::U8(v) => v.len(),
            NpyData::Bool(v) => v.len(),
            NpyData::Unicode(v) => v.len(),
        }
    }

    /// `true` when there are no elements.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The NumPy `descr` this data is written with (`<U{n}` uses the longest string, at least 1).
    pub fn descr(&self) -> String {
        match self {
            NpyData::F16(_) => "<f2".into(),
            NpyData::F32(_) => "<f4".into(),
            NpyData::F64(_) => "<f8".into(),
            NpyData::I64(_) => "<i8".into(),
            NpyData::I32(_) => "<i4".into(),
            NpyData::U32(_) => "<u4".into(),
            NpyData::U8(_) => "|u1".into(),
            NpyData::Bool(_) => "|b1".into(),
            NpyData::Unicode(v) => format!("<U{}", unicode_width(v)),
        }
    }
}

fn unicode_width(v: &[String]) -> usize {
    v.iter()
        .map(|s| s.chars().count())
        .max()
        .unwrap_or(0)
        .max(1)
}

/// An n-dimensional array: shape plus elements in C order. A 0-d array has `shape == []` and one
/// element.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// Dimensions (empty for a 0-d scalar).
    pub shape: Vec<usize>,
    /// Elements in C (row-major) order; `len == shape.iter().product()`.
    pub data: NpyData,
}

impl NpyArray {
    /// Builds an array, checking that the element count matches the shape.
    pub fn new(shape: Vec<usize>, data: NpyData) -> Result<Self, String> {
        let n: usize = shape.iter().product();
        if n != data.len() {
            return Err(format!(
                "shape {shape:?} needs {n} elements but {} were given",
                data.len()
            ));
        }
        Ok(Self { shape, data })
    }

    /// A 0-d unicode array holding `s` (how NumPy saves a Python `str`, e.g. a JSON config).
    pub fn scalar_str(s: &str) -> Self {
        Self {
            shape: vec![],
            data: NpyData::Unicode(vec![s.to_owned()]),
        }
    }

    /// An `(n, 3)` `<f4` array.
    pub fn f32_rows3(rows: &[[f32; 3]]) -> Self {
        Self {
            shape: vec![rows.len(), 3],
            data: NpyData::F32(rows.iter().flatten().copied().collect()),
        }
    }

    /// An `(n, 3)` `<f8` array.
    pub fn f64_rows3(rows: &[[f64; 3]]) -> Self {
        Self {
            shape: vec![rows.len(), 3],
            data: NpyData::F64(rows.iter().flatten().copied().collect()),
        }
    }

    /// An `(n, 3)` `<i8` array from `u32` indices.
    pub fn i64_rows3(rows: &[[u32; 3]]) -> Self {
        Self {
            shape: vec![rows.len(), 3],
            data: NpyData::I64(rows.iter().flatten().map(|&i| i64::from(i)).collect()),
        }
    }

    /// The string of a 0-d (or one-element) unicode array.
    pub fn as_str(&self) -> Option<&str> {
        match &self.data {
            NpyData::Unicode(v) if v.len() == 1 => Some(&v[0]),
            _ => None,
        }
    }

    /// All elements converted to `f64` (integers and booleans too); `None` for strings.
    pub fn to_f64_vec(&self) -> Option<Vec<f64>> {
        Some(match &self.data {
            NpyData::F16(v) => v.iter().map(|&x| f64::from(x)).collect(),
            NpyData::F32(v) => v.iter().map(|&x| f64::from(x)).collect(),
            NpyData::F64(v) => v.clone(),
            NpyData::I64(v) => v.iter().map(|&x| x as f64).collect(),
            NpyData::I32(v) => v.iter().map(|&x| f64::from(x)).collect(),
            NpyData::U32(v) => v.iter().map(|&x| f64::from(x)).collect(),
            NpyData::U8(v) => v.iter().map(|&x| f64::from(x)).collect(),
            NpyData::Bool(v) => v.iter().map(|&x| f64::from(u8::from(x))).collect(),
            NpyData::Unicode(_) => return None,
        })
    }

    /// Floating-point elements as `f32` (`<f2` widened exactly, `<f8` rounded to nearest); `None`
    /// for integers, booleans and strings.
    pub fn to_f32(&self) -> Option<Vec<f32>> {
        match &self.data {
            NpyData::F16(v) => Some(v.iter().map(|x| x.to_f32()).collect()),
            NpyData::F32(v) => Some(v.clone()),
            NpyData::F64(v) => Some(v.iter().map(|&x| x as f32).collect()),
            _ => None,
        }
    }

    /// The elements of an `<i8` array, borrowed (`None` for any other dtype).
    pub fn as_i64(&self) -> Option<&[i64]> {
        match &self.data {
            NpyData::I64(v) => Some(v),
            _ => None,
        }
    }

    /// Integer elements as `i64` (`None` for floats and strings).
    pub fn to_i64_vec(&self) -> Option<Vec<i64>> {
        Some(match &self.data {
            NpyData::I64(v) => v.clone(),
            NpyData::I32(v) => v.iter().map(|&x| i64::from(x)).collect(),
            NpyData::U32(v) => v.iter().map(|&x| i64::from(x)).collect(),
            NpyData::U8(v) => v.iter().map(|&x| i64::from(x)).collect(),
            _ => return None,
        })
    }
}

/// Serializes an array as `.npy` version 1.0 (3.0 if the header needs it; it never does for the
/// dtypes here), header padded to a multiple of 64 bytes, little-endian, C order.
pub fn write_npy(a: &NpyArray) -> Vec<u8> {
    let shape = match a.shape.len() {
        0 => "()".to_string(),
        1 => format!("({},)", a.shape[0]),
        _ => format!(
            "({})",
            a.shape
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let mut header = format!(
        "{{'descr': '{}', 'fortran_order': False, 'shape': {}, }}",
        a.data.descr(),
        shape
    );
    // magic(6) + version(2) + len(2) + header + '\n' ≡ 0 (mod 64)
    let unpadded = 10 + header.len() + 1;
    let pad = (64 - unpadded % 64) % 64;
    header.extend(std::iter::repeat_n(' ', pad));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + a.data.len() * 8);
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    // The header of the dtypes written here is always far below 65535 bytes.
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    match &a.data {
        NpyData::F16(v) => v
            .iter()
            .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
        NpyData::F32(v) => v
            .iter()
            .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
        NpyData::F64(v) => v
            .iter()
            .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
        NpyData::I64(v) => v
            .iter()
            .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
        NpyData::I32(v) => v
            .iter()
            .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
        NpyData::U32(v) => v
            .iter()
            .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
        NpyData::U8(v) => out.extend_from_slice(v),
        NpyData::Bool(v) => out.extend(v.iter().map(|&b| u8::from(b))),
        NpyData::Unicode(v) => {
            let w = unicode_width(v);
            for s in v {
                let mut n = 0;
                for c in s.chars() {
                    out.extend_from_slice(&(c as u32).to_le_bytes());
                    n += 1;
                }
                for _ in n..w {
                    out.extend_from_slice(&0u32.to_le_bytes());
                }
            }
        }
    }
    out
}

/// A Python literal value in an `.npy` header dict.
#[derive(Debug, PartialEq)]
enum Lit {
    Str(String),
    Bool(bool),
    Tuple(Vec<usize>),
}

/// Parses the header dict `{'key': value, ...}` with string, bool and int-tuple values.
fn parse_header_dict(s: &str) -> Result<Vec<(String, Lit)>, String> {
    let b = s.trim().as_bytes();
    let mut i = 0usize;
    let skip_ws = |i: &mut usize| {
        while *i < b.len() && (b[*i] as char).is_ascii_whitespace() {
            *i += 1;
        }
    };
    let parse_str = |i: &mut usize| -> Result<String, String> {
        let q = b[*i];
        *i += 1;
        let start = *i;
        while *i < b.len() && b[*i] != q {
            *i += 1;
        }
        if *i >= b.len() {
            return Err("unterminated string in header".into());
        }
        let out = String::from_utf8_lossy(&b[start..*i]).into_owned();
        *i += 1;
        Ok(out)
    };
    skip_ws(&mut i);
    if b.get(i) != Some(&b'{') {
        return Err("header is not a Python dict (no '{')".into());
    }
    i += 1;
    let mut out = Vec::new();
    loop {
        skip_ws(&mut i);
        match b.get(i) {
            Some(b'}') => break,
            Some(b'\'') | Some(b'"') => {}
            _ => return Err("expected a quoted key or '}' in header".into()),
        }
        let key = parse_str(&mut i)?;
        skip_ws(&mut i);
        if b.get(i) != Some(&b':') {
            return Err(format!("expected ':' after key '{key}' in header"));
        }
        i += 1;
        skip_ws(&mut i);
        let val =
            match b.get(i) {
                Some(b'\'') | Some(b'"') => Lit::Str(parse_str(&mut i)?),
                Some(b'(') => {
                    i += 1;
                    let mut dims = Vec::new();
                    loop {
                        skip_ws(&mut i);
                        match b.get(i) {
                            Some(b')') => {
                                i += 1;
                                break;
                            }
                            Some(b',') => i += 1,
                            Some(c) if c.is_ascii_digit() => {
                                let start = i;
                                while i < b.len() && b[i].is_ascii_digit() {
                                    i += 1;
                                }
                                // `L` suffix of Python 2 longs.
                                let digits = std::str::from_utf8(&b[start..i]).unwrap_or("");
                                if b.get(i) == Some(&b'L') {
                                    i += 1;
                                }
                                dims.push(digits.parse::<usize>().map_err(|_| {
                                    format!("shape dimension {digits} is too large")
                                })?);
                            }
                            _ => return Err("malformed shape tuple in header".into()),
                        }
                    }
                    Lit::Tuple(dims)
                }
                _ if b[i..].starts_with(b"True") => {
                    i += 4;
                    Lit::Bool(true)
                }
                _ if b[i..].starts_with(b"False") => {
                    i += 5;
                    Lit::Bool(false)
                }
                _ => return Err(format!("unsupported value for key '{key}' in header")),
            };
        out.push((key, val));
        skip_ws(&mut i);
        match b.get(i) {
            Some(b',') => i += 1,
            Some(b'}') => break,
            _ => return Err("expected ',' or '}' in header".into()),
        }
    }
    Ok(out)
}

/// Parses a complete `.npy` file. Errors are plain messages; the caller adds the file and key.
pub fn parse_npy(bytes: &[u8]) -> Result<NpyArray, String> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err("not a .npy array (missing the \\x93NUMPY magic)".into());
    }
    let major = bytes[6];
    let (hlen, hstart) = match major {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10usize),
        2 | 3 => {
            if bytes.len() < 12 {
                return Err("truncated .npy header".into());
            }
            (
                u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
                12usize,
            )
        }
        v => {
            return Err(format!(
                ".npy format version {v} is not supported (1, 2 or 3)"
            ));
        }
    };
    let hend = hstart
        .checked_add(hlen)
        .filter(|&e| e <= bytes.len())
        .ok_or_else(|| "truncated .npy header".to_string())?;
    let header = std::str::from_utf8(&bytes[hstart..hend])
        .map_err(|_| "the .npy header is not valid text".to_string())?;
    let dict = parse_header_dict(header)?;
    let get = |k: &str| dict.iter().find(|(key, _)| key == k).map(|(_, v)| v);
    let descr = match get("descr") {
        Some(Lit::Str(s)) => s.clone(),
        _ => {
            return Err(
                "header has no 'descr' string (structured dtypes are not supported)".into(),
            );
        }
    };
    let shape = match get("shape") {
        Some(Lit::Tuple(t)) => t.clone(),
        _ => return Err("header has no 'shape' tuple".into()),
    };
    let fortran = match get("fortran_order") {
        Some(Lit::Bool(b)) => *b,
        _ => return Err("header has no 'fortran_order' flag".into()),
    };
    if fortran && shape.iter().filter(|&&d| d > 1).count() > 1 {
        return Err(format!(
            "array of shape {shape:?} is stored in Fortran (column-major) order, which is not \
             supported; save it with np.ascontiguousarray(a)"
        ));
    }
    let n = shape
        .iter()
        .try_fold(1usize, |acc, &d| acc.checked_mul(d))
        .ok_or_else(|| format!("shape {shape:?} is too large"))?;
    let body = &bytes[hend..];
    let (order, kind) = descr.split_at(descr.len().min(1));
    if order == ">" {
        return Err(format!(
            "dtype '{descr}' is big-endian, which is not supported; save it as little-endian \
             (a.astype(a.dtype.newbyteorder('<')))"
        ));
    }
    if !matches!(order, "<" | "|" | "=") {
        return Err(format!("unsupported dtype '{descr}'"));
    }
    let need = |size: usize| -> Result<&[u8], String> {
        let total = n
            .checked_mul(size)
            .ok_or_else(|| format!("shape {shape:?} is too large"))?;
        if body.len() < total {
            return Err(format!(
                "truncated data: shape {shape:?} of '{descr}' needs {total} bytes, the file has {}",
                body.len()
            ));
        }
        Ok(&body[..total])
    };
    macro_rules! le {
        ($t:ty, $size:expr) => {
            need($size)?
                .chunks_exact($size)
                .map(|c| <$t>::from_le_bytes(c.try_into().unwrap_or([0; $size])))
                .collect()
        };
    }
    let data = match kind {
        "f2" => NpyData::F16(le!(half::f16, 2)),
        "f4" => NpyData::F32(le!(f32, 4)),
        "f8" => NpyData::F64(le!(f64, 8)),
        "i8" => NpyData::I64(le!(i64, 8)),
        "i4" => NpyData::I32(le!(i32, 4)),
        "u4" => NpyData::U32(le!(u32, 4)),
        "u1" => NpyData::U8(need(1)?.to_vec()),
        "b1" => NpyData::Bool(need(1)?.iter().map(|&x| x != 0).collect()),
        k if k.starts_with('U') => {
            let w: usize = k[1..]
                .parse()
                .map_err(|_| format!("malformed unicode dtype '{descr}'"))?;
            let raw = need(w.checked_mul(4).ok_or("unicode width too large")?)?;
            if w == 0 && n > body.len().max(1 << 16) {
                // Zero-width strings take no bytes, so the shape alone would size the array.
                return Err(format!(
                    "shape {shape:?} of zero-width '{descr}' holds more elements than the file could mean"
                ));
            }
            let mut strings = Vec::with_capacity(n);
            if w > 0 {
                for elem in raw.chunks_exact(w * 4) {
                    let mut s = String::new();
                    for cu in elem.chunks_exact(4) {
                        let c = u32::from_le_bytes([cu[0], cu[1], cu[2], cu[3]]);
                        s.push(char::from_u32(c).ok_or_else(|| {
                            format!("invalid code point {c:#x} in unicode array")
                        })?);
                    }
                    let trimmed = s.trim_end_matches('\0').len();
                    s.truncate(trimmed);
                    strings.push(s);
                }
            } else {
                strings.resize(n, String::new());
            }
            NpyData::Unicode(strings)
        }
        _ => {
            return Err(format!(
                "unsupported dtype '{descr}' (supported: <f2 <f4 <f8 <i8 <i4 <u4 |u1 |b1 <U…)"
            ));
        }
    };
    Ok(NpyArray { shape, data })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_dtype_round_trips_through_bytes_with_64_byte_aligned_header() {
        let arrays = vec![
            NpyArray::new(
                vec![2, 3],
                NpyData::F32(vec![1.0, -2.5, 3.0, f32::MAX, 0.0, -0.0]),
            ),
            NpyArray::new(
                vec![3],
                NpyData::F64(vec![1e-300, f64::MIN_POSITIVE, -7.25]),
            ),
            NpyArray::new(vec![1, 2], NpyData::I64(vec![i64::MIN, i64::MAX])),
            NpyArray::new(vec![2], NpyData::I32(vec![-1, 7])),
            NpyArray::new(
                vec![3],
                NpyData::F16(vec![
                    half::f16::from_f32(0.5),
                    half::f16::MAX,
                    half::f16::from_f32(-1e-3),
                ]),
            ),
            NpyArray::new(vec![2], NpyData::U32(vec![u32::MAX, 0])),
            NpyArray::new(vec![2, 2, 1], NpyData::U8(vec![0, 1, 254, 255])),
            NpyArray::new(vec![3], NpyData::Bool(vec![true, false, true])),
            NpyArray::new(vec![0, 3], NpyData::F32(vec![])),
            NpyArray::new(vec![2], NpyData::Unicode(vec!["λ=8 ✓".into(), "".into()])),
        ];
        for a in arrays {
            let a = a.expect("consistent shape");
            let bytes = write_npy(&a);
            let hlen = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
            assert_eq!((10 + hlen) % 64, 0, "data must start 64-byte aligned");
            assert_eq!(bytes[10 + hlen - 1], b'\n');
            assert_eq!(parse_npy(&bytes).expect("parses"), a);
        }
        let s = NpyArray::scalar_str("{\"lamb\": 8.0}");
        assert_eq!(
            parse_npy(&write_npy(&s)).expect("parses").as_str(),
            Some("{\"lamb\": 8.0}")
        );
    }

    #[test]
    fn header_written_matches_numpy_byte_for_byte() {
        // What numpy 1.x/2.x writes for np.save(f, np.zeros((1839, 3), np.float32)).
        let a = NpyArray::f32_rows3(&vec![[0.0; 3]; 1839]);
        let bytes = write_npy(&a);
        let expected = format!(
            "{{'descr': '<f4', 'fortran_order': False, 'shape': (1839, 3), }}{}\n",
            " ".repeat(55)
        );
        assert_eq!(&bytes[..10], b"\x93NUMPY\x01\x00v\x00");
        assert_eq!(
            std::str::from_utf8(&bytes[10..128]).ok(),
            Some(expected.as_str())
        );
    }

    #[test]
    fn unicode_is_utf32le_null_padded() {
        let a =
            NpyArray::new(vec![2], NpyData::Unicode(vec!["ab".into(), "é".into()])).expect("shape");
        let bytes = write_npy(&a);
        let hlen = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        let body = &bytes[10 + hlen..];
        assert_eq!(body, &[97, 0, 0, 0, 98, 0, 0, 0, 0xe9, 0, 0, 0, 0, 0, 0, 0]);
        assert!(String::from_utf8_lossy(&bytes[..10 + hlen]).contains("'<U2'"));
    }

    #[test]
    fn big_endian_fortran_truncated_and_garbage_give_clear_errors() {
        let mut be = write_npy(&NpyArray::new(vec![1], NpyData::F32(vec![1.0])).expect("shape"));
        let pos = be
            .windows(3)
            .position(|w| w == b"<f4")
            .expect("descr present");
        be[pos] = b'>';
        assert!(
            parse_npy(&be)
                .expect_err("bad input must be rejected")
                .contains("big-endian")
        );

        let mut f =
            write_npy(&NpyArray::new(vec![2, 2], NpyData::F64(vec![0.0; 4])).expect("shape"));
        let pos = f
            .windows(5)
            .position(|w| w == b"False")
            .expect("flag present");
        f.splice(pos..pos + 5, b"True ".iter().copied());
        assert!(
            parse_npy(&f)
                .expect_err("bad input must be rejected")
                .contains("Fortran")
        );

        let full = write_npy(&NpyArray::f32_rows3(&[[1.0, 2.0, 3.0]]));
        assert!(
            parse_npy(&full[..full.len() - 1])
                .expect_err("bad input must be rejected")
                .contains("truncated")
        );
        assert!(
            parse_npy(&full[..20])
                .expect_err("bad input must be rejected")
                .contains("truncated")
        );
        assert!(
            parse_npy(b"PK\x03\x04 not an array")
                .expect_err("bad input must be rejected")
                .contains("magic")
        );
        assert!(parse_npy(&[]).is_err());
    }

    #[test]
    fn version_2_headers_and_python2_long_dims_parse() {
        let header = "{'descr': '<i4', 'fortran_order': False, 'shape': (2L,), }\n";
        let mut bytes = b"\x93NUMPY\x02\x00".to_vec();
        bytes.extend_from_slice(&(header.len() as u32).to_le_bytes());
        bytes.extend_from_slice(header.as_bytes());
        bytes.extend_from_slice(&5i32.to_le_bytes());
        bytes.extend_from_slice(&(-6i32).to_le_bytes());
        let a = parse_npy(&bytes).expect("parses");
        assert_eq!(a.shape, vec![2]);
        assert_eq!(a.data, NpyData::I32(vec![5, -6]));
    }
}
