//! splat-train: what training shares across methods: the photometric loss with its gradient and the
//! evaluation metrics ([`loss`]), Adam ([`adam`]), where training starts ([`init`]), adaptive
//! density control ([`densify`]) or MCMC ([`mcmc`]), checkpoints ([`checkpoint`]), what a run learns per view (its exposure, [`per_view`]), where a
//! step's time goes ([`step_times`]), batches of views ([`batch`]) shared among processes
//! ([`team`]), and the loop with the trait a method implements to take part ([`fit`]), also
//! on the GPU ([`gpu_fit`], with the loss, Adam, density control's
//! statistics and MCMC's terms on the device in [`device`]).

pub mod adam;
pub mod batch;
pub mod checkpoint;
pub mod densify;
#[cfg(feature = "gpu")]
pub mod device;
pub mod fit;
#[cfg(feature = "gpu")]
pub mod gpu_fit;
#[cfg(feature = "gpu")]
pub mod hardware_fit;
pub mod init;
pub mod like_3dgs;
pub mod loss;
pub mod mcmc;
pub mod per_view;
pub mod sharded;
pub mod step_times;
pub mod team;
pub mod trainable;

pub use checkpoint::Checkpoint;
pub use densify::DensifyOptions;
pub use fit::{FitOptions, Strategy};
pub use mcmc::McmcOptions;
pub use step_times::StepTimes;
pub use trainable::{Rate, Shape, Trainable};

/// What [`like_3dgs!`] expands to names, from the crates it does not re-export.
#[doc(hidden)]
pub mod __private {
    pub use splat_core::glam::{Vec2, Vec3};
    pub use splat_core::method::SplatMethod;
    pub use splat_io::ply::{FromStored, StoredGaussian, ToStored};
}
