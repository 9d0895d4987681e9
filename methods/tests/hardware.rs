//! The hardware-rasterized forward pass (quads in depth order, fixed-function blending into
//! render targets of each precision) against the tile-based forward on the GPU, within the
//! bound each target format implies (`hardware_forward_matches_tiles`): 3DGS (no pixel data)
//! and 3DGUT (its `pixel_info` rays, on a fisheye) through the same check; and the same pass
//! with programmable blending (the fragments blend themselves, in rasterization order).
//!
//! Needs a wgpu adapter (lavapipe is enough); with `SPLAT_REQUIRE_GPU=1` a missing adapter
//! fails the test, otherwise it skips (programmable blending: `SPLAT_REQUIRE_RASTER_ORDER=1`).

use crate::common::{
    GAUSSIAN_GROUPS, as_method, camera_groups, covering_gaussians, spread_gaussians, wide_camera,
};
use splat_methods::{geer, gs3d, gut};
use splat_runtime::CameraModel;
use splat_runtime::blend::Blend;
use splat_runtime::checks::bound::Bound;
use splat_runtime::checks::forward::hardware_forward_matches_tiles;
use splat_runtime::checks::gradients::{
    FINITE_DIFFERENCES, GPU_GRADIENTS, hardware_gradients_match_finite_differences,
    hardware_gradients_match_tiles,
};
use splat_runtime::gpu::entries::FragmentReduction;
use splat_runtime::gpu::raster::{Blending, HardwareRenderer};
use splat_runtime::gpu::{GpuScene, adapter_or_skip, programmable_blend};
use splat_runtime::precision::Precision;
use splat_runtime::{RenderOptions, render};

#[test]
fn hardware_forward_matches_the_tile_path_in_every_format() {
    let cam = wide_camera(64, 48, CameraModel::Pinhole);
    let params = spread_gaussians(&cam, 300, 4);
    let fixed = Blending::FixedFunction;
    let formats = hardware_forward_matches_tiles::<gs3d::Method>("3dgs", &params, &cam, fixed);
    if adapter_or_skip().is_some() {
        // Rgba16Float and Rgba8Unorm blend on every adapter.
        assert!(formats.iter().any(|(p, _)| *p == Precision::F16));
        assert!(formats.iter().any(|(p, _)| *p == Precision::Unorm8));
    }
    let fisheye = wide_camera(64, 48, CameraModel::KannalaBrandt);
    let rays = as_method::<gut::Params>(spread_gaussians(&fisheye, 300, 5));
    hardware_forward_matches_tiles::<gut::Method>("3dgut, fisheye", &rays, &fisheye, fixed);
}

/// Programmable blending (each fragment reads its pixel's targets and writes the blend, in
/// rasterization order) within the same bounds of the tile path, in every format, through a
/// pinhole (3DGS) and a fisheye (3DGUT, whose fragments read the camera's rays).
#[test]
fn programmable_blending_matches_the_tile_path_in_every_format() {
    let cam = wide_camera(64, 48, CameraModel::Pinhole);
    let params = spread_gaussians(&cam, 300, 4);
    let programmable = Blending::Programmable;
    let formats =
        hardware_forward_matches_tiles::<gs3d::Method>("3dgs", &params, &cam, programmable);
    if programmable_blend::open_or_skip().is_some() {
        assert_eq!(
            formats.len(),
            Precision::ALL.len(),
            "every format, blendable or not"
        );
    }
    for (precision, worst) in &formats {
        println!(
            "3dgs, programmable, {}: worst {worst:.3} of the bound",
            precision.name()
        );
    }
    let fisheye = wide_camera(64, 48, CameraModel::KannalaBrandt);
    let rays = as_method::<gut::Params>(spread_gaussians(&fisheye, 300, 5));
    hardware_forward_matches_tiles::<gut::Method>("3dgut, fisheye", &rays, &fisheye, programmable);
}

/// The image of the default hardware path equals the CPU's (with its transmittance stop)
/// within what the stop leaves out, and options it cannot honour are refused by name.
#[test]
fn hardware_forward_renders_what_the_cpu_renders_and_refuses_p_max() {
    let Some(gpu) = adapter_or_skip() else {
        return;
    };
    let cam = wide_camera(40, 32, CameraModel::Pinhole);
    let params = spread_gaussians(&cam, 120, 6);
    let opts = RenderOptions::default();
    let cpu = render::<gs3d::Method>(&params, &cam, &opts).unwrap();
    let precision = if splat_runtime::gpu::raster::supports(&gpu, Precision::F32) {
        Precision::F32
    } else {
        Precision::F16
    };
    let mut hw =
        HardwareRenderer::<gs3d::Method>::new(&gpu, &RenderOptions { precision, ..opts }).unwrap();
    let scene = GpuScene::new(&gpu, &params).unwrap();
    hw.forward(&scene, &cam).unwrap();
    let frame = hw.download_frame().unwrap();
    // Past the stop, at most T_MIN of transmittance is left to add color; f16 rounds too.
    let bound = 1e-4 + 2.0 * 64.0 * precision.unit_error().max(2f32.powi(-24)) + 1e-5;
    for (a, b) in cpu.color.data.iter().zip(&frame.color.data) {
        assert!((a - b).abs() <= bound, "{a} / {b}");
    }
    let capped = RenderOptions {
        p_max: Some(8),
        ..opts
    };
    let err = HardwareRenderer::<gs3d::Method>::new(&gpu, &capped)
        .err()
        .unwrap();
    assert!(err.to_string().contains("P_max"), "{err}");
}

/// With a stack deep enough that pixels stop (the stop changes the image by more than the
/// check's bound), programmable blending stops them where the tile path does.
#[test]
fn programmable_blending_stops_pixels_where_the_tile_path_does() {
    let cam = wide_camera(32, 24, CameraModel::Pinhole);
    let params = spread_gaussians(&cam, 2000, 7);
    let stop = render::<gs3d::Method>(&params, &cam, &RenderOptions::default()).unwrap();
    let no_stop = RenderOptions {
        blend: Blend {
            t_min: 0.0,
            ..Blend::default()
        },
        ..RenderOptions::default()
    };
    let all = render::<gs3d::Method>(&params, &cam, &no_stop).unwrap();
    let diffs: Vec<f32> = stop
        .color
        .data
        .iter()
        .zip(&all.color.data)
        .map(|(a, b)| (a - b).abs())
        .collect();
    let changed = diffs.iter().filter(|d| **d > 1e-4).count();
    println!(
        "the stop changed {changed} of {} values, most by {:e}",
        diffs.len(),
        diffs.iter().fold(0.0f32, |a, b| a.max(*b))
    );
    assert!(changed > 0);
    hardware_forward_matches_tiles::<gs3d::Method>(
        "3dgs, deep",
        &params,
        &cam,
        Blending::Programmable,
    );
}

/// The hardware backward (the programmable forward replayed in fragment shaders) against the
/// tile path's gradients, in every state format, through a pinhole (3DGS) and a fisheye
/// (3DGUT: its camera gradient also flows through the pixels' rays), with each way of summing
/// the fragments' gradients before the atomics (the seed's Table I: the sums must cut the
/// atomics, the hybrid never issuing more than the quads; and where no subgroup sums, as with
/// a threshold none reaches, each falls back atomic for atomic); and each against the f64 reference
/// (the seed's Table IV). f32 states are held to the GPU's f32 bound; narrower ones to
/// [`narrow_state`].
#[test]
fn hardware_backward_matches_the_tile_path_in_every_format() {
    let bound = |p: Precision| match p {
        Precision::F32 => GPU_GRADIENTS,
        _ => narrow_state(p),
    };
    let cam = wide_camera(64, 48, CameraModel::Pinhole);
    let params = spread_gaussians(&cam, 300, 4);
    let fisheye = wide_camera(64, 48, CameraModel::KannalaBrandt);
    let rays = as_method::<gut::Params>(spread_gaussians(&fisheye, 300, 5));
    let required = programmable_blend::open_or_skip().is_some();
    // Every way, and the subgroup's with a threshold no subgroup reaches: what a subgroup that
    // does not sum does (lavapipe's are all cohesive).
    let never = 1000;
    let ways: Vec<_> = (FragmentReduction::ALL.into_iter())
        .chain([
            FragmentReduction::Subgroup { min_lanes: never },
            FragmentReduction::Hybrid { min_lanes: never },
        ])
        .collect();
    let gs = hardware_gradients_match_tiles::<gs3d::Method>("3dgs", &params, &cam, &ways, bound);
    let label = "3dgut, fisheye";
    let gut = hardware_gradients_match_tiles::<gut::Method>(label, &rays, &fisheye, &ways, bound);
    if required {
        // The tile path's, then every format's in every way.
        let rows = 1 + Precision::ALL.len() * ways.len();
        assert_eq!(gs.len(), rows, "every format and reduction");
        assert_eq!(gut.len(), rows, "every format and reduction");
    }
    for (label, fits) in [("3dgs", &gs), ("3dgut, fisheye", &gut)] {
        for f in fits {
            let path = f
                .reduce
                .map_or("tiles".into(), |r| format!("hardware, {r:?}"));
            println!(
                "{label}, {path}, {}: {:.3} of the bound, {} atomics, {:.2e} of the group's largest off f64",
                f.precision.name(),
                f.of_bound,
                f.atomics,
                f.off_f64
            );
        }
        if fits.is_empty() {
            continue; // no programmable blending here
        }
        // Measured on lavapipe (3DGS, f32 states): 440,580 atomics one per fragment, 139,870
        // with the quads' sums, 85,440 with the subgroups' and the hybrid's (llvmpipe's
        // 8-lane subgroups hold two quads of one triangle: every one cohesive).
        for precision in Precision::ALL {
            let atomics = |way| {
                let row = (fits.iter()).find(|f| f.reduce == Some(way) && f.precision == precision);
                row.map_or(0, |f| f.atomics)
            };
            let [none, quad, subgroup, hybrid, no_subgroup, no_hybrid] =
                <[_; 6]>::try_from(ways.clone())
                    .expect("six ways")
                    .map(atomics);
            assert!(
                2 * quad < none,
                "{label}, {precision:?}: the quads' sums cut the atomics: {quad} of {none}"
            );
            assert!(
                subgroup < none,
                "{label}, {precision:?}: the subgroups' sums cut the atomics: {subgroup} of {none}"
            );
            assert!(
                hybrid <= quad.min(subgroup),
                "{label}, {precision:?}: the hybrid is the least: {hybrid} against {quad} and {subgroup}"
            );
            // Where no subgroup sums, each falls back word for word.
            assert_eq!(
                no_subgroup, none,
                "{label}, {precision:?}: subgroups falling back to fragments"
            );
            assert_eq!(
                no_hybrid, quad,
                "{label}, {precision:?}: the hybrid falling back to quads"
            );
        }
    }
}

/// The hardware backward (f32 states, the default sums) against central differences of the
/// f64 reference on smooth scenes (every Gaussian over every pixel, clear of the thresholds),
/// within the bound the CPU's backward is held to: 3DGS through a pinhole, 3DGUT through a
/// fisheye (every camera field, the distortion's through the rays), 3DGEER through an
/// equiangular lens. Measured on lavapipe: 0.28 of the bound (3DGUT's distortion), 0.07
/// (3DGEER's rotation), 0.06 (3DGS's rotation).
#[test]
fn hardware_gradients_match_finite_differences_on_smooth_scenes() {
    use hardware_gradients_match_finite_differences as check;
    let required = programmable_blend::open_or_skip().is_some();
    let cam = |model| wide_camera(24, 16, model);
    let (pinhole, fisheye, equiangular) = (
        cam(CameraModel::Pinhole),
        cam(CameraModel::KannalaBrandt),
        cam(CameraModel::Equiangular),
    );
    let (groups, fd) = (&GAUSSIAN_GROUPS, FINITE_DIFFERENCES);
    let gs = covering_gaussians(&pinhole);
    let gut: Vec<gut::Params> = as_method(covering_gaussians(&fisheye));
    let geer: Vec<geer::Params> = as_method(covering_gaussians(&equiangular));
    let ran = [
        check::<gs3d::Method>(
            "hardware, 3dgs",
            &gs,
            &pinhole,
            groups,
            camera_groups(pinhole.model),
            fd,
        ),
        check::<gut::Method>(
            "hardware, 3dgut",
            &gut,
            &fisheye,
            groups,
            camera_groups(fisheye.model),
            fd,
        ),
        check::<geer::Method>(
            "hardware, 3dgeer",
            &geer,
            &equiangular,
            groups,
            camera_groups(equiangular.model),
            fd,
        ),
    ];
    assert!(ran.iter().all(|r| *r) || !required);
}

/// The hardware backward's gradients with states narrower than f32 against the tile path's
/// f32 ones: within 400 rounding units of each group's largest element, the unit being the
/// coarser of the colors' format and the depth sums' f16. Every stored value of the state the
/// replay reads is off by up to 2n units after n layers (the forward's bound), and what lies
/// behind a fragment (a difference of two stored values) is divided by 1 - alpha. Measured on
/// lavapipe (2026-12-07): 0.48 of this bound (3DGUT's distortion gradient on the fisheye, f16
/// states: 4.7% of the group's largest), unorm16 0.38, unorm8 0.14 (3DGUT's focal length).
fn narrow_state(p: Precision) -> Bound {
    let unit = p.unit_error().max(Precision::F16.unit_error());
    Bound::new(0.0, 400.0 * unit as f64)
}
