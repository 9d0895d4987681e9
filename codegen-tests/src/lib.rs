//! Tests of what `#[splat_method]` / `#[splat_functions]` generate.
//!
//! - [`corpus`]: annotated functions covering every operator, intrinsic and control-flow form.
//! - [`check`]: the gradient checks (central finite differences of the f64 twin, and the
//!   dot-product identity) and the lane-vs-scalar comparison, generic over any kernel's flat
//!   form.
//! - [`samples`]: each corpus function's random inputs, shared by the CPU and GPU checks.
//!
//! The method-level tests use `splat_examples::isotropic`, a small complete method.

pub mod check;
pub mod corpus;
pub mod samples;
