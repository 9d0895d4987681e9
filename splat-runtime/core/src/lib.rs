//! splat-core: the contract ([`SplatMethod`]) between generated methods and the backends, and
//! what both backends agree on. Depends on no other splat crate but the camera models'.
//!
//! - [`method`]: the contract a generated method implements.
//! - [`types`]: built-in values crossing that contract (camera, projected primitive,
//!   contribution of a pair, tile bounds).
//! - [`cameras`]: the camera models' functions.
//! - [`flat`]: flattening of method data to 32-bit words (GPU buffers, SIMD lanes).
//! - [`lanes`]: eight-lane SIMD value types used by the generated lane form of `evaluate`.
//! - [`math`]: branch-free `exp` / `ln` shared by the scalar and lane code paths.
//! - [`prelude`]: what a method module imports.
//! - [`frame`]: render options, errors and their checks, outputs, output gradients.
//! - [`grid`], [`blend`], [`precision`]: the tile grid and tile lists, the blend's thresholds,
//!   the storage formats of per-pixel and per-primitive values.
//! - [`effects`]: which effects a method and camera put in play.

pub mod blend;
pub mod cameras;
pub mod effects;
pub mod flat;
pub mod frame;
pub mod grid;
pub mod lanes;
pub mod math;
pub mod method;
pub mod precision;
pub mod prelude;
pub mod types;

pub use effects::Effects;
pub use flat::Flat;
pub use frame::{Frame, FrameGrad, Gradients, Image, RenderError, RenderOptions};
pub use glam;
pub use lanes::{F32x8, I32x8, LANES, LaneArray, M32x8, U32x8};
pub use method::{
    GeneratedSource, GradientSet, SplatMethod, WgslFunction, WgslScalar, param_group, param_groups,
    word_name,
};
pub use types::{Camera, CameraModel, Contribution, ContributionLanes, Projected, Tile};
