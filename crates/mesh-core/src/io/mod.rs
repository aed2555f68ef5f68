//! Mesh files: read by extension (`obj`, `off`, `ply`, `gltf`, `glb`), write `obj`, `off`, `ply`,
//! `glb`; [`Format`] is the list of formats and what each can do.
//!
//! Readers return the file's vertices **in file order** (vertex `i` of the file is vertex `i` of the
//! mesh, unreferenced ones included) and its polygons fan-triangulated. They do not validate: run
//! [`crate::validate::repair`] (or `validate`) before computing anything on a user's mesh. Face
//! indices are stored as read, so a file with an out-of-range index loads and validation reports it.
//! Truncated or malformed files give a [`MeshError`] naming the file and what was expected.

mod format;
mod gltf;
mod obj;
mod off;
mod ply;

use std::path::Path;

use crate::{MeshError, TriMesh};

pub use format::Format;
pub use gltf::{read_gltf, read_gltf_with_parts, write_glb, write_glb_with_colors};
pub use obj::{read_obj, read_obj_with_parts, write_obj};
pub use off::{read_off, write_off};
pub use ply::{PlyEncoding, read_ply, read_ply_with_parts, write_ply};

use crate::region::Parts;

/// A mesh and, when the file stores one per vertex, its vertex normals.
pub type MeshWithNormals = (TriMesh, Option<Vec<[f64; 3]>>);

/// The readable [`Format`]s, as [`MeshError::UnsupportedFormat`] lists them (a test checks it
/// against [`Format::can_read`]).
const READ_FORMATS: &str = "obj, off, ply, gltf, glb";
/// The writable [`Format`]s (checked against [`Format::can_write`]).
const WRITE_FORMATS: &str = "obj, off, ply, glb";

/// Lower-cased extension of `path` ("" when there is none).
fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

/// Reads a triangle mesh, choosing the format by extension. See the module docs for what is kept.
pub fn read_mesh(path: impl AsRef<Path>) -> Result<TriMesh, MeshError> {
    read_mesh_with_normals(path).map(|(m, _)| m)
}

/// Like [`read_mesh`], also returning per-vertex normals when the file stores exactly one normal
/// per vertex (OBJ `vn` used consistently per vertex, PLY `nx ny nz`, glTF `NORMAL` on every
/// primitive).
pub fn read_mesh_with_normals(path: impl AsRef<Path>) -> Result<MeshWithNormals, MeshError> {
    let path = path.as_ref();
    let ext = extension(path);
    let out = match Format::from_extension(&ext) {
        Some(Format::Obj) => read_obj(path)?,
        Some(Format::Off) => read_off(path)?,
        Some(Format::Ply) => read_ply(path)?,
        Some(Format::Gltf | Format::Glb) => read_gltf(path)?,
        None => {
            return Err(MeshError::UnsupportedFormat {
                path: path.to_path_buf(),
                extension: ext,
                supported: READ_FORMATS,
            });
        }
    };
    if out.0.faces.is_empty() {
        return Err(MeshError::Empty {
            path: path.to_path_buf(),
        });
    }
    Ok(out)
}

/// Like [`read_mesh`], also returning the parts the file offers for regions
/// ([`crate::region`]): OBJ `o`/`g`/`usemtl`, glTF named nodes and meshes, PLY scalar vertex and
/// face properties (OFF offers none). Indices are in the file's numbering, as the mesh's.
pub fn read_mesh_with_parts(path: impl AsRef<Path>) -> Result<(TriMesh, Parts), MeshError> {
    let path = path.as_ref();
    let ((mesh, _), parts) = match Format::from_path(path) {
        Some(Format::Obj) => read_obj_with_parts(path)?,
        Some(Format::Ply) => read_ply_with_parts(path)?,
        Some(Format::Gltf | Format::Glb) => read_gltf_with_parts(path)?,
        Some(Format::Off) | None => (read_mesh_with_normals(path)?, Parts::default()),
    };
    if mesh.faces.is_empty() {
        return Err(MeshError::Empty {
            path: path.to_path_buf(),
        });
    }
    Ok((mesh, parts))
}

/// Writes a mesh, choosing the format by extension, with optional per-vertex normals (one per
/// vertex). Missing parent folders are created. PLY is written as `binary_little_endian` (use
/// [`write_ply`] for ASCII); OFF cannot store normals (they are ignored).
pub fn write_mesh(
    path: impl AsRef<Path>,
    mesh: &TriMesh,
    normals: Option<&[[f64; 3]]>,
) -> Result<(), MeshError> {
    let path = path.as_ref();
    if let Some(n) = normals
        && n.len() != mesh.positions.len()
    {
        return Err(MeshError::LengthMismatch {
            what: "normals (one per vertex)",
            expected: mesh.positions.len(),
            got: n.len(),
        });
    }
    let ext = extension(path);
    let Some(format) = Format::from_extension(&ext).filter(|f| f.can_write()) else {
        return Err(MeshError::UnsupportedFormat {
            path: path.to_path_buf(),
            extension: ext,
            supported: WRITE_FORMATS,
        });
    };
    create_parent_dirs(path)?;
    match format {
        Format::Obj => write_obj(path, mesh, normals),
        Format::Off => write_off(path, mesh),
        Format::Ply => write_ply(path, mesh, normals, PlyEncoding::BinaryLittleEndian),
        Format::Glb => write_glb(path, mesh, normals),
        Format::Gltf => Err(MeshError::UnsupportedFormat {
            path: path.to_path_buf(),
            extension: ext,
            supported: WRITE_FORMATS,
        }),
    }
}

/// Creates the parent folders of `path` if they are missing.
pub(crate) fn create_parent_dirs(path: &Path) -> Result<(), MeshError> {
    if let Some(parent) = path.parent()
        && !parent.as_os_str().is_empty()
    {
        std::fs::create_dir_all(parent).map_err(|error| MeshError::Io {
            path: parent.to_path_buf(),
            error,
        })?;
    }
    Ok(())
}

/// Checks, without opening it, that `path` is a regular file (a directory, named pipe, socket or
/// device is refused, saying which). One definition, in the `npy` crate (which must not depend on
/// mesh code), shared by every reader of a user-named file.
pub use npy::ensure_regular_file;

/// Opens `path` for reading after [`ensure_regular_file`].
pub fn open_regular(path: &Path) -> Result<std::fs::File, MeshError> {
    ensure_regular_file(path).map_err(|e| io_err(path, e))?;
    std::fs::File::open(path).map_err(|e| io_err(path, e))
}

/// Reads a whole regular file (see [`open_regular`]).
pub(crate) fn read_bytes(path: &Path) -> Result<Vec<u8>, MeshError> {
    use std::io::Read;
    let mut file = open_regular(path)?;
    let mut bytes = Vec::new();
    file.read_to_end(&mut bytes).map_err(|e| io_err(path, e))?;
    Ok(bytes)
}

/// `bytes` without a leading UTF-8 byte-order mark (which some Windows tools write at the start of
/// text files; left in place it would hide the first record).
pub(crate) fn strip_bom(bytes: &[u8]) -> &[u8] {
    bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes)
}

/// A parse error for `path`.
pub(crate) fn parse_err(path: &Path, message: impl Into<String>) -> MeshError {
    MeshError::Parse {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Text formats: a parse error on the last line of a file that does not end with a newline most
/// likely means the file was cut off; say so.
pub(crate) fn truncation_hint(e: MeshError, bytes: &[u8]) -> MeshError {
    match e {
        MeshError::Parse { path, message }
            if !bytes.is_empty()
                && !bytes.ends_with(b"\n")
                && message.starts_with(&format!(
                    "line {}:",
                    bytes.iter().filter(|&&b| b == b'\n').count() + 1
                )) =>
        {
            MeshError::Parse {
                path,
                message: format!(
                    "{message} (the last line is incomplete: the file looks truncated)"
                ),
            }
        }
        e => e,
    }
}

/// An I/O error for `path`.
pub(crate) fn io_err(path: &Path, error: std::io::Error) -> MeshError {
    MeshError::Io {
        path: path.to_path_buf(),
        error,
    }
}
