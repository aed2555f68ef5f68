//! `.npz` files through the [`npy`] crate (re-exported here), and the reference's saved-deformation
//! layout (spec §8), [`SavedDeformation`]. Errors of the `npy` crate become [`MeshError`]s with the
//! same message (`Io` stays `Io`, a bad archive is `Parse`, a bad array is `Npy`).

mod saved;

pub use npy::npz::{MAX_ENTRY_BYTES, NpzReader, NpzWriter, write_npz};
pub use npy::{NpyArray, NpyData, parse_npy, write_npy};
pub use saved::{FORMAT_VERSION, MAX_EXTRA_BYTES, SavedDeformation};

use crate::MeshError;

impl From<npy::NpyError> for MeshError {
    fn from(e: npy::NpyError) -> Self {
        match e {
            npy::NpyError::Io { path, error } => MeshError::Io { path, error },
            npy::NpyError::Archive { path, message } => MeshError::Parse { path, message },
            npy::NpyError::Array { path, key, message } => MeshError::Npy { path, key, message },
        }
    }
}
