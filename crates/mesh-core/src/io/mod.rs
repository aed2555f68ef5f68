//! Mesh files: read by extension (`obj`, `off`, `ply`, `gltf`, `glb`), write `obj`, `ply`, `glb`.
//!
//! Readers return the file's vertices **in file order** (vertex `i` of the file is vertex `i` of the
//! mesh, unreferenced ones included) and its polygons fan-triangulated. They do not validate: run
//! [`crate::validate::repair`] (or `validate`) before computing anything on a user's mesh. Face
//! indices are stored as read, so a file with an out-of-range index loads and validation reports it.
//! Truncated or malformed files give a [`MeshError`] naming the file and what was expected.

mod obj;

use std::path::Path;

use crate::{MeshError, TriMesh};

pub use obj::{read_obj, write_obj};

/// A mesh and, when the file stores one per vertex, its vertex normals.
pub type MeshWithNormals = (TriMesh, Option<Vec<[f64; 3]>>);

const READ_FORMATS: &str = "obj";
const WRITE_FORMATS: &str = "obj";

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
/// per vertex (OBJ `vn` used consistently per vertex).
pub fn read_mesh_with_normals(path: impl AsRef<Path>) -> Result<MeshWithNormals, MeshError> {
    let path = path.as_ref();
    let ext = extension(path);
    let out = match ext.as_str() {
        "obj" => read_obj(path)?,
        _ => {
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

/// Writes a mesh, choosing the format by extension, with optional per-vertex normals (one per
/// vertex). Missing parent folders are created.
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
    match ext.as_str() {
        "obj" => {
            create_parent_dirs(path)?;
            write_obj(path, mesh, normals)
        }
        _ => Err(MeshError::UnsupportedFormat {
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
        std::fs::create_dir_all(parent).map_err(|source| MeshError::Io {
            path: parent.to_path_buf(),
            source,
        })?;
    }
    Ok(())
}

/// Reads a whole file.
pub(crate) fn read_bytes(path: &Path) -> Result<Vec<u8>, MeshError> {
    std::fs::read(path).map_err(|source| MeshError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// A parse error for `path`.
pub(crate) fn parse_err(path: &Path, message: impl Into<String>) -> MeshError {
    MeshError::Parse {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// An I/O error for `path`.
pub(crate) fn io_err(path: &Path, source: std::io::Error) -> MeshError {
    MeshError::Io {
        path: path.to_path_buf(),
        source,
    }
}
