//! The methods' integration tests, one module per subject, built as one test binary: each
//! binary links the runtime and instantiates its generic pipeline for the methods it tests, so
//! one binary compiles every (stage, method) pair once where sixteen compiled most of them
//! again.

mod common;

mod antialiased;
mod colmap;
mod ewa_cameras;
mod extremes;
mod fisheye_fold;
mod fit;
mod geer;
mod gpu_parity;
mod gradients;
mod gut;
mod hard_cases;
mod hardware;
mod independent_reference;
mod lens;
mod linprim;
mod per_view;
mod precision;
mod reference;
mod rolling_shutter;
mod sharded;
mod slices;
mod suite;
mod variants;
