//! The `SplatMethod` glue of a generated method: lane forms against scalar forms, the lane
//! adjoint's reduction, the projection's gradient (camera included), and a snapshot of the
//! generated Rust so every change to the emitters shows up in review.

use codegen_tests::check::{gradient, uniform};
use splat_examples::isotropic::isotropic::{self, Method, Shade};
use splat_runtime::glam::{Vec2, Vec3};
use splat_runtime::{Contribution, ContributionLanes, F32x8, LANES, M32x8, SplatMethod};

fn random_shade(rng: &mut fastrand::Rng) -> Shade {
    Shade {
        center: Vec2::new(rng.f32() * 16.0, rng.f32() * 16.0),
        inv_sigma2: 0.02 + 0.2 * rng.f32(),
        opacity: 0.2 + 0.8 * rng.f32(),
        color: Vec3::new(rng.f32(), rng.f32(), rng.f32()),
    }
}

fn random_pixels(rng: &mut fastrand::Rng) -> ([Vec2; LANES], [F32x8; 2]) {
    let px: [Vec2; LANES] = std::array::from_fn(|_| Vec2::new(rng.f32() * 16.0, rng.f32() * 16.0));
    let lanes = [F32x8(px.map(|p| p.x)), F32x8(px.map(|p| p.y))];
    (px, lanes)
}

#[test]
fn evaluate_lanes_equals_evaluate_bit_for_bit() {
    let mut rng = fastrand::Rng::with_seed(3);
    for _ in 0..200 {
        let shade = random_shade(&mut rng);
        let (px, lanes) = random_pixels(&mut rng);
        let out = Method::evaluate_lanes(&lanes, &shade);
        for (l, p) in px.iter().enumerate() {
            let s = Method::evaluate(p, &shade);
            assert_eq!(s.alpha.to_bits(), out.alpha.lane(l).to_bits());
            for c in 0..3 {
                assert_eq!(s.color[c].to_bits(), out.color[c].lane(l).to_bits());
            }
            assert_eq!(s.valid, out.valid.lane(l));
        }
    }
}

#[test]
fn evaluate_adjoint_lanes_sums_the_active_lanes() {
    let mut rng = fastrand::Rng::with_seed(4);
    for _ in 0..200 {
        let shade = random_shade(&mut rng);
        let (px, lanes) = random_pixels(&mut rng);
        let d: [Contribution<Vec3>; LANES] = std::array::from_fn(|_| Contribution {
            alpha: rng.f32() - 0.5,
            color: Vec3::new(rng.f32(), rng.f32(), rng.f32()),
            valid: true,
        });
        let active = M32x8::from(std::array::from_fn(|_| rng.bool()));
        let d_lanes = ContributionLanes {
            alpha: F32x8(d.map(|x| x.alpha)),
            color: [0, 1, 2].map(|c| F32x8(d.map(|x| x.color[c]))),
            valid: M32x8::splat(true),
        };
        let got = Method::evaluate_adjoint_lanes(&lanes, &shade, &d_lanes, active);
        let mut want = [0.0f32; 7];
        for l in 0..LANES {
            if !active.lane(l) {
                continue;
            }
            let g = Method::evaluate_adjoint(&px[l], &shade, &d[l]);
            let flat = [
                g.center.x,
                g.center.y,
                g.inv_sigma2,
                g.opacity,
                g.color.x,
                g.color.y,
                g.color.z,
            ];
            for (w, v) in want.iter_mut().zip(flat) {
                *w += v;
            }
        }
        let got = [
            got.center.x,
            got.center.y,
            got.inv_sigma2,
            got.opacity,
            got.color.x,
            got.color.y,
            got.color.z,
        ];
        assert_eq!(got, want);
    }
}

#[test]
fn project_gradient_matches_finite_differences_including_the_camera() {
    // Inputs: params (mean 3, log_radius, color 3, opacity_logit) then the camera (rotation 9,
    // translation 3, focal 2, principal 2, size 2, distortion 4, shutter turn 3 and shift 3),
    // all perturbed; the camera model (the one integer slot) is pinhole.
    let sample = |r: &mut fastrand::Rng| {
        let mut x: [f64; 8 + splat_runtime::Camera::FLOAT_SLOTS] = uniform(r, -0.5, 0.5);
        for (i, v) in x[8..17].iter_mut().enumerate() {
            *v = if i % 4 == 0 { 1.0 } else { 0.1 * *v };
        }
        x[19] = 3.0 + r.f64(); // translation.z keeps the point in front
        x[20] = 100.0 + 50.0 * r.f64();
        x[21] = 100.0 + 50.0 * r.f64();
        (x, [0])
    };
    let report = gradient(
        isotropic::twin::project,
        isotropic::twin::project_adjoint,
        sample,
        11,
        20,
    );
    println!("{report:?}");
    assert!(
        report.jacobian <= 1e-6 && report.dot_product <= 1e-6,
        "{report:?}"
    );
}

#[test]
fn method_reports_its_shape() {
    assert_eq!(Method::NAME, "isotropic");
    const { assert!(Method::HAS_TILE_CULL && !Method::HAS_PIXEL_INFO) };
    assert_eq!(<Shade as splat_runtime::Flat>::LEN, 7);
    assert!(Method::SOURCE.rust.contains("pub fn evaluate_adjoint"));
}

#[test]
fn generated_rust_snapshot() {
    insta::assert_snapshot!(isotropic::GENERATED_RUST);
}

/// The parameter groups are the fields of `Params`, named and sized as declared.
#[test]
fn param_groups_are_the_declared_fields() {
    let want = [
        ("mean", 0..3),
        ("log_radius", 3..4),
        ("color", 4..7),
        ("opacity_logit", 7..8),
    ];
    assert_eq!(splat_runtime::param_groups::<Method>(), want);
}

/// The box and the tile cull hold every pixel the 1/255 threshold keeps, on opaque splats too
/// (whose footprint reaches past three sigma), and the cull drops some tiles of the boxes.
#[test]
fn the_box_and_the_cull_hold_every_kept_pixel() {
    use splat_runtime::checks::forward::{
        boxes_hold_every_contributing_pixel, tile_cull_is_conservative,
    };
    let cam = splat_runtime::Camera {
        focal: Vec2::splat(64.0),
        principal: Vec2::new(32.0, 24.0),
        size: Vec2::new(64.0, 48.0),
        ..Default::default()
    };
    let mut rng = fastrand::Rng::with_seed(5);
    let params: Vec<isotropic::Params> = (0..80)
        .map(|_| {
            let z = 2.0 + 4.0 * rng.f32();
            let at = Vec2::new(rng.f32() * 1.2 - 0.6, rng.f32() * 0.9 - 0.45);
            isotropic::Params {
                mean: (at * z).extend(z),
                log_radius: -3.5 + 1.5 * rng.f32(),
                color: Vec3::new(rng.f32(), rng.f32(), rng.f32()),
                opacity_logit: 8.0 * rng.f32() - 3.0,
            }
        })
        .collect();
    let outside =
        boxes_hold_every_contributing_pixel::<Method>("isotropic", &params, &cam, 1.0 / 255.0);
    assert!(outside > 0, "the boxes should leave pixels out");
    for (with, without) in tile_cull_is_conservative::<Method>("isotropic", &params, &cam) {
        assert!(
            with < without,
            "the cull dropped nothing ({with} of {without})"
        );
    }
}
