//! The mesh file formats, named by extension: the one list every reader, writer and command uses.

use std::path::Path;

/// A mesh file format, chosen by the file's extension (ASCII case-insensitive: `.OBJ` is OBJ).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Format {
    /// Wavefront OBJ (`.obj`): read and written, with vertex normals.
    Obj,
    /// Object File Format (`.off`): read and written, without normals.
    Off,
    /// Stanford PLY (`.ply`): read (ASCII and binary) and written (binary little-endian), with
    /// vertex normals.
    Ply,
    /// glTF 2.0 as JSON with its buffers beside it (`.gltf`): read only.
    Gltf,
    /// glTF 2.0 binary (`.glb`): read and written, with vertex normals.
    Glb,
}

impl Format {
    /// Every format, in the order messages list them.
    pub const ALL: [Format; 5] = [
        Format::Obj,
        Format::Off,
        Format::Ply,
        Format::Gltf,
        Format::Glb,
    ];

    /// The formats a result mesh is written in: those that are written with vertex normals
    /// (OBJ, PLY, GLB).
    pub const WITH_NORMALS: [Format; 3] = [Format::Obj, Format::Ply, Format::Glb];

    /// The format of an extension (without the dot), ASCII case-insensitive.
    pub fn from_extension(extension: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|f| f.extension().eq_ignore_ascii_case(extension))
    }

    /// The format of `path`, by its extension (None without one, or for another extension).
    pub fn from_path(path: &Path) -> Option<Self> {
        path.extension()
            .and_then(|e| e.to_str())
            .and_then(Self::from_extension)
    }

    /// The extension, lower case, without the dot (`"obj"`).
    pub fn extension(self) -> &'static str {
        match self {
            Format::Obj => "obj",
            Format::Off => "off",
            Format::Ply => "ply",
            Format::Gltf => "gltf",
            Format::Glb => "glb",
        }
    }

    /// Whether [`super::read_mesh`] reads it (every format does).
    pub fn can_read(self) -> bool {
        true
    }

    /// Whether [`super::write_mesh`] writes it (all but `.gltf`).
    pub fn can_write(self) -> bool {
        self != Format::Gltf
    }

    /// Whether a written file keeps per-vertex normals (all written formats but OFF).
    pub fn writes_normals(self) -> bool {
        self.can_write() && self != Format::Off
    }

    /// Whether the reader offers the file's parts for regions (OBJ groups, PLY properties, glTF
    /// nodes and meshes; OFF has none).
    pub fn has_parts(self) -> bool {
        self != Format::Off
    }

    /// `formats`' extensions for a message: each after `prefix` (`"."` or `""`), separated by
    /// `", "`, the last two by `last` (`" or "`, or `", "` for a plain list):
    /// `list(&Format::WITH_NORMALS, ".", " or ")` is `".obj, .ply or .glb"`.
    pub fn list(formats: &[Format], prefix: &str, last: &str) -> String {
        let mut out = String::new();
        for (i, f) in formats.iter().enumerate() {
            if i > 0 {
                out.push_str(if i + 1 == formats.len() { last } else { ", " });
            }
            out.push_str(prefix);
            out.push_str(f.extension());
        }
        out
    }
}

impl std::fmt::Display for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.extension())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extensions_round_trip_case_insensitively() {
        for f in Format::ALL {
            assert_eq!(Format::from_extension(f.extension()), Some(f));
            let upper = f.extension().to_ascii_uppercase();
            assert_eq!(
                Format::from_path(Path::new(&format!("a/b.{upper}"))),
                Some(f)
            );
        }
        assert_eq!(Format::from_extension("stl"), None);
        assert_eq!(Format::from_path(Path::new("mesh")), None);
        assert_eq!(Format::from_path(Path::new("obj")), None);
    }

    #[test]
    fn lists_read_as_the_messages_do() {
        assert_eq!(
            Format::list(&Format::WITH_NORMALS, ".", " or "),
            ".obj, .ply or .glb"
        );
        assert_eq!(
            Format::list(&Format::ALL, ".", ", "),
            ".obj, .off, .ply, .gltf, .glb"
        );
        assert_eq!(Format::list(&[Format::Obj], "", " or "), "obj");
        let readable: Vec<Format> = Format::ALL.into_iter().filter(|f| f.can_read()).collect();
        assert_eq!(
            Format::list(&readable, "", ", "),
            super::super::READ_FORMATS
        );
        let writable: Vec<Format> = Format::ALL.into_iter().filter(|f| f.can_write()).collect();
        assert_eq!(
            Format::list(&writable, "", ", "),
            super::super::WRITE_FORMATS
        );
        let with_normals: Vec<Format> = Format::ALL
            .into_iter()
            .filter(|f| f.writes_normals())
            .collect();
        assert_eq!(with_normals, Format::WITH_NORMALS);
    }
}
