//! The camera models (each defined once in the `splat-cameras` crate, whose text the compiler
//! reads too): what [`Camera::project_point`](crate::Camera) and its siblings call, one module
//! per model with its `CODE`, `NAME`, `DISTORTION` and functions, and the functions every model
//! shares (the pose, the rolling shutter).

use crate::prelude::*;

splat_cameras::camera_models!();
