//! The commands that run a method: each checks its flags, finds the method (`crate::methods`),
//! reads what it works on and hands the method's instance its job (`crate::render::Render`,
//! `crate::bench::Bench`, `crate::tradeoff::Tradeoff`, `crate::fit::Fit`). Jobs never name a
//! method or a command, so the methods' table can hold them.

pub(crate) mod bench;
pub(crate) mod convert;
pub(crate) mod eval;
pub(crate) mod fit;
pub(crate) mod render;
pub(crate) mod tradeoff;
pub(crate) mod video;
pub(crate) mod view;
