//! What goes wrong reading a dataset, each error naming the file and the field.

use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    #[error("cannot read {path}: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("cannot write {path}: {error}")]
    Write { path: PathBuf, error: String },
    #[error(transparent)]
    Output(crate::image::ImageError),
    #[error("{path} is not valid JSON: {error}")]
    Json {
        path: PathBuf,
        error: serde_json::Error,
    },
    #[error(
        "{0} is not a dataset: it holds neither transforms_train.json (Blender) nor transforms.json (nerfstudio) nor a COLMAP model in sparse/0 or sparse (cameras, images and points3D, .bin or .txt)"
    )]
    NotADataset(PathBuf),
    #[error("{path}: {field} {problem}")]
    Field {
        path: PathBuf,
        field: String,
        problem: String,
    },
    #[error("cannot decode the image {path}: {error}")]
    Image {
        path: PathBuf,
        error: image::ImageError,
    },
    #[error("{path} is {}x{} pixels, the first image of {file} is {}x{}", got.0, got.1, want.0, want.1)]
    Size {
        path: PathBuf,
        file: PathBuf,
        got: (u32, u32),
        want: (u32, u32),
    },
    #[error("{0} holds no frames")]
    Empty(PathBuf),
}

pub(crate) fn field(
    path: &Path,
    field: impl Into<String>,
    problem: impl Into<String>,
) -> DatasetError {
    DatasetError::Field {
        path: path.to_path_buf(),
        field: field.into(),
        problem: problem.into(),
    }
}

/// A picture's width and height, read from its header.
pub(crate) fn image_size(path: &Path) -> Result<(u32, u32), DatasetError> {
    image::image_dimensions(path).map_err(|error| image_error(path, error))
}

pub(crate) fn image_error(path: &Path, error: image::ImageError) -> DatasetError {
    match error {
        image::ImageError::IoError(error) => DatasetError::Io {
            path: path.to_path_buf(),
            error,
        },
        error => DatasetError::Image {
            path: path.to_path_buf(),
            error,
        },
    }
}
