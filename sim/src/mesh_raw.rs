//! What every mesh reader returns and how it says a file is wrong: shared by `crate::mesh` (glTF,
//! OBJ, STL and the dispatch by extension) and `crate::mesh_mjcf` (MuJoCo `.msh`, MJCF objects),
//! so neither file imports the other's items in a circle.

use std::path::Path;

use crate::error::SimError;

/// Vertices (z-up, scaled) and triangles of a mesh file.
pub(crate) type Raw = (Vec<[f64; 3]>, Vec<[u32; 3]>);

/// A mesh file's reader: vertices and triangles of the file at `path`, times `scale`.
pub(crate) type ReadRaw = fn(&Path, f64) -> Result<Raw, SimError>;

pub(crate) fn mesh_error(path: &Path, message: String) -> SimError {
    SimError::Mesh {
        path: path.to_path_buf(),
        message,
    }
}
