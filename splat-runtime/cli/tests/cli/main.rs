//! The `splat` command end to end, one module per command (one test binary, so the command line and
//! its 16 method instances are linked once): every output format, every kind of bad input (a clear
//! error, a non-zero exit, no output file), and what each command promises.

mod bench;
mod common;
mod convert;
mod dataset;
mod eval;
mod fit;
mod gallery;
mod inspect;
#[cfg(feature = "mpi")]
mod mpi;
mod outputs;
mod render;
mod tradeoff;
mod video;
mod view;
