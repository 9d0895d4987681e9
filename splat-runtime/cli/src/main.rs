//! `splat`: the command line with the built-in methods.

use splat_cli::{Instance, Method};
use splat_methods::{
    geer, geer_rs, geer_sh0, geer_sh1, geer_sh2, gs3d, gs3d_aa, gs3d_sh0, gs3d_sh1, gs3d_sh2, gut,
    gut_rs, gut_sh0, gut_sh1, gut_sh2, linprim,
};
use std::process::ExitCode;

fn main() -> ExitCode {
    splat_cli::run(&[
        Method::per_sh_degree(
            "3dgs",
            "3D Gaussian Splatting (EWA, SH up to degree 3); every camera",
            vec![
                Instance::of::<gs3d_sh0::Method>(),
                Instance::of::<gs3d_sh1::Method>(),
                Instance::of::<gs3d_sh2::Method>(),
                Instance::trainable::<gs3d::Method>(),
            ],
        ),
        Method::new(
            "3dgs-aa",
            "3DGS anti-aliased (Mip-Splatting's 2D filter, gsplat's `antialiased`); every camera",
            Instance::trainable::<gs3d_aa::Method>(),
        )
        .antialiased(),
        Method::per_sh_degree(
            "3dgut",
            "3DGUT: unscented-transform projection, evaluation along camera rays; every camera",
            vec![
                Instance::of::<gut_sh0::Method>(),
                Instance::of::<gut_sh1::Method>(),
                Instance::of::<gut_sh2::Method>(),
                Instance::trainable::<gut::Method>(),
            ],
        )
        .with_rolling_shutter(Instance::of::<gut_rs::Method>()),
        Method::new(
            "linprim",
            "LinPrim: octahedra (each Gaussian of the scene becomes one); pinhole only",
            Instance::trainable::<linprim::Method>(),
        )
        .primitives("octahedra"),
        Method::per_sh_degree(
            "3dgeer",
            "3DGEER: exact ray integral, particle bounding frustums; every camera",
            vec![
                Instance::of::<geer_sh0::Method>(),
                Instance::of::<geer_sh1::Method>(),
                Instance::of::<geer_sh2::Method>(),
                Instance::trainable::<geer::Method>(),
            ],
        )
        .with_rolling_shutter(Instance::of::<geer_rs::Method>())
        .exact(),
    ])
}
