//! Why virtual objects could not be built: [`ObjectError`], returned by the mesh loader
//! and by an object's placement alike.

use std::path::PathBuf;

/// Why virtual objects could not be built.
#[derive(Debug, thiserror::Error)]
pub enum ObjectError {
    #[error("cannot read the mesh `{}`: {source}", path.display())]
    MeshUnreadable {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("the mesh `{}` is not a valid OBJ file: {reason}", path.display())]
    MeshInvalid { path: PathBuf, reason: String },
    #[error("the mesh `{}` has no triangles", path.display())]
    MeshEmpty { path: PathBuf },
    #[error(
        "the mesh `{}` has no triangle with an area: all {count} have repeated or collinear corners",
        path.display()
    )]
    MeshDegenerate { path: PathBuf, count: usize },
    #[error("object `{object}`: {message}")]
    InvalidSpec { object: String, message: String },
}
