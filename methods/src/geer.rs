// 3DGEER (Huang et al. 2025): the exact ray integral of each Gaussian, with the particle bounding
// frustum (PBF, App. D.1) for the bounding box and for the per-tile association, on every
// camera model.
//
// - `evaluate`: in the Gaussian's canonical frame the density integrated along the whole line
//   is exp(-D²/2), D² = |o_u × d_u|² / |d_u|² (eq. B.7, B.9), computed through the cross
//   product (App. C.7: the expanded |o_u|²|d_u|² - (o_u·d_u)² cancels catastrophically for
//   flat Gaussians). The ray starts at the camera, so the integral over t >= 0 is that times
//   Φ(s*), the normal CDF of the signed canonical distance s* = -o_u·d_u / |d_u| of the
//   closest point: 1 for particles well in front, 0 behind the camera, continuous between.
// - `project`: the tangent planes of the λ-contour through the camera give the horizontal and
//   vertical angular bounds (eq. 10); each root is taken on the branch nearest the centre's
//   angle (the mirror transform of App. D.2), so bounds past 90° stay ordered. The box is their
//   image: exact for the pinhole and equiangular (BEAP) models; for the fisheye, the image of
//   the cone around the centre's direction that holds the contour.
// - `tile_cull`: the contour against the four planes through the camera and the tile's edges
//   (the PBF-CSF test); exact for pinhole and BEAP, every tile kept for the fisheye, whose
//   tile edges are not planes.
//
// - A rolling shutter, as for 3DGUT, is an instance of its own: `geer_rs` integrates each
//   pixel along the ray of the pose the camera had when its row was read (`cam.shutter_time`);
//   the box holds the boxes seen from the first and the last row's pose; the tile cull tests
//   the contour seen from the first row's pose, grown by how far any of its points can move
//   by the tile's last row (the slide, plus the turn's angle times the distance: the planes
//   of a tile's rays pass through the camera centre of the moment); color and opacity are
//   those seen from the first row's pose.
//
// The SH degree is one instance per degree, as for 3DGS: `geer_sh0` .. `geer_sh2`, and `geer`
// for degree 3 (and the rolling shutter).

/// One 3DGEER method with `$n` SH coefficients per channel, with or without a rolling shutter.
macro_rules! exact {
    ($name:ident, sh_coefficients = $n:literal, rolling_shutter = $rs:literal) => {
        #[splat_macros::splat_method(name = "3dgeer")]
        pub mod $name {
            use splat_runtime::prelude::*;

            pub const NEAR: f32 = 0.01;
            pub const ALPHA_MIN: f32 = 1.0 / 255.0;
            pub const PI: f32 = std::f32::consts::PI;
            /// Stands for an unbounded box side (the runtime clamps boxes to the image).
            pub const FAR: f32 = 1e6;
            /// See each row from the camera's pose at the row's readout.
            pub const ROLLING_SHUTTER: bool = $rs;

            pub struct Params {
                pub mean: Vec3,
                pub log_scale: Vec3,
                /// Rotation quaternion (w, x, y, z), normalized here.
                pub rotation: Vec4,
                pub opacity_logit: f32,
                pub sh: [Vec3; $n],
            }

            pub struct Ray {
                /// World-space direction.
                pub dir: Vec3,
                /// Where it starts, from the camera centre: the rolling shutter's motion by the
                /// row's time (zero without one).
                pub shift: Vec3,
            }

            pub struct Cull {
                /// Camera-space mean and λ² Σ (the contour where alpha reaches ALPHA_MIN).
                pub mean: Vec3,
                pub contour: Mat3,
                pub focal: Vec2,
                pub principal: Vec2,
                /// How tile edges map to angles: 0 atan (pinhole), 1 none (fisheye), 2 linear (BEAP).
                pub edges: f32,
                /// With a rolling shutter: how far any point of the contour moves, in the
                /// camera's frame, from the first row's pose to the last's, and the rows
                /// (time runs from 0 at the top edge to 1 at the bottom).
                pub motion: f32,
                pub rows: f32,
            }

            pub struct Shade {
                /// The camera centre in the canonical frame, and world to canonical (S^-1 R^T).
                pub origin: Vec3,
                pub whiten: Mat3,
                pub opacity: f32,
                pub color: Vec3,
            }

            /// Angular bounds (lo, hi) of the wedge holding the contour, from the tangent condition
            /// a c² - 2 b c + e = 0 in c = tan(angle), whose discriminant b² - a e is `disc`. Each
            /// root is a plane, known mod pi; on the branches nearest `centre` both can land on one
            /// side of it (a wedge reaching past 90° from the centre's angle, as for particles
            /// beside a wide camera): then the wedge holding the centre is the narrower one, and the
            /// farther bound moves by pi. Unless `narrow` (the contour's bounding sphere is clear of
            /// the camera axis the planes turn about: its wedge is within 90° of the centre), where
            /// both on one side is rounding (a contour collapsed to a point) and the wedge is
            /// widened to hold the centre.
            fn bounds(a: f32, b: f32, disc: f32, centre: f32, narrow: bool) -> Vec2 {
                let root = disc.max(0.0).sqrt();
                let one = nearest_branch(a, b + root, centre);
                let other = nearest_branch(a, b - root, centre);
                let (lo, hi) = (one.min(other), one.max(other));
                let (below, above) = (hi < centre && !narrow, lo > centre && !narrow);
                Vec2::new(
                    select(below, hi, select(above, hi - PI, lo.min(centre))),
                    select(below, lo + PI, select(above, lo, hi.max(centre))),
                )
            }

            /// The tangent condition's discriminant b² - a e for the contour's entries `cuu`,
            /// `cuz`, `czz` and the mean's `mu`, `mz` in the plane of one image axis u (a = czz - mz²,
            /// b = cuz - mu mz, e = cuu - mu²), written without the mu² mz² terms that cancel: the
            /// contour's quadratic form at (mz, -mu) less its minor. Negative when the camera's
            /// other axis crosses the contour; for a collapsed contour the form (about |C| |m|²)
            /// outweighs the minor (|C|²) and keeps it positive, where b² - a e is rounding noise.
            fn tangent_discriminant(cuu: f32, cuz: f32, czz: f32, mu: f32, mz: f32) -> f32 {
                cuu * mz * mz + czz * mu * mu - 2.0 * cuz * mu * mz - (cuu * czz - cuz * cuz)
            }

            /// The angle with tangent num / a closest to `centre` (tan repeats every pi).
            fn nearest_branch(a: f32, num: f32, centre: f32) -> f32 {
                let (s, c) = (centre.sin(), centre.cos());
                let rel = (num * c - a * s).atan2(a * c + num * s);
                centre
                    + select(
                        rel > PI / 2.0,
                        rel - PI,
                        select(rel < -PI / 2.0, rel + PI, rel),
                    )
            }

            /// r(θ) of the fisheye, in focal units.
            fn fisheye_radius(k: Vec4, theta: f32) -> f32 {
                let t2 = theta * theta;
                theta * (1.0 + t2 * (k.x + t2 * (k.y + t2 * (k.z + t2 * k.w))))
            }

            /// The fisheye image of the cone of half-angle `half` around camera-space `dir`: an
            /// annular sector; its box from the sector's corners and the outer arc's axis crossings.
            fn fisheye_box(cam: &Camera, dir: Vec3, half: f32) -> (Vec2, Vec2) {
                let polar = (dir.x * dir.x + dir.y * dir.y).sqrt().atan2(dir.z);
                let azimuth = dir.y.atan2(dir.x);
                let outer = fisheye_radius(cam.distortion, (polar + half).min(PI));
                let inner = fisheye_radius(cam.distortion, (polar - half).max(0.0));
                // The sector's half-width in azimuth; all around when the cone holds the axis (either
                // end of it).
                let around = half >= polar || polar + half >= PI;
                let spread = select(around, PI, (half.sin() / polar.sin()).min(1.0).asin());
                let mut lo = Vec2::splat(FAR);
                let mut hi = Vec2::splat(-FAR);
                let sides = [-1.0, 1.0, -1.0, 1.0];
                let radii = [inner, inner, outer, outer];
                for k in 0..4 {
                    let angle = azimuth + sides[k] * spread;
                    let p =
                        cam.principal + cam.focal * Vec2::new(angle.cos(), angle.sin()) * radii[k];
                    lo = lo.min(p);
                    hi = hi.max(p);
                }
                for k in 0..4 {
                    // The outer arc's axis crossings inside the sector.
                    let angle = PI / 2.0 * k as f32;
                    let off = (angle - azimuth).sin().atan2((angle - azimuth).cos()).abs();
                    let p = cam.principal + cam.focal * Vec2::new(angle.cos(), angle.sin()) * outer;
                    lo = select(off <= spread, lo.min(p), lo);
                    hi = select(off <= spread, hi.max(p), hi);
                }
                (lo, hi)
            }

            /// The particle bounding frustum seen from one pose of the camera.
            pub struct Frustum {
                /// The image box of the contour.
                pub lo: Vec2,
                pub hi: Vec2,
                /// Camera-space mean and λ² Σ.
                pub mean: Vec3,
                pub contour: Mat3,
                /// The mean in front of the near plane and where the camera can project it.
                pub seen: bool,
            }

            /// The PBF of the contour `lambda2` (λ²) of the Gaussian at `p.mean` with axes
            /// `rot` scaled by `scale`, from the pose (`rotation`, `translation`) of `cam`.
            fn frustum(
                p: &Params,
                rot: Mat3,
                scale: Vec3,
                lambda2: f32,
                rotation: Mat3,
                translation: Vec3,
                cam: &Camera,
            ) -> Frustum {
                let mean = rotation * p.mean + translation;
                let axes = rotation * rot * Mat3::from_diagonal(scale);
                let contour = axes * axes.transpose() * lambda2;
                let t = contour - Mat3::from_cols(mean * mean.x, mean * mean.y, mean * mean.z);
                // No tangent plane through the camera's y (x) axis when that axis crosses the
                // contour: every horizontal (vertical) angle is reached. Both: the camera is inside.
                let (cx, cy, cz) = (contour.x_axis, contour.y_axis, contour.z_axis);
                let disc = Vec2::new(
                    tangent_discriminant(cx.x, cz.x, cz.z, mean.x, mean.z),
                    tangent_discriminant(cy.y, cz.y, cz.z, mean.y, mean.z),
                );
                let open = Vec2::new(
                    select(disc.x < 0.0, FAR, 0.0),
                    select(disc.y < 0.0, FAR, 0.0),
                );
                let inside = open.min_element() > 0.0;
                // The contour's bounding sphere (radius² lambda2 s_max²) clear of the y (x) axis.
                let r2 = lambda2 * scale.max_element() * scale.max_element();
                let (mx, my, mz) = (mean.x * mean.x, mean.y * mean.y, mean.z * mean.z);
                let (narrow_x, narrow_y) = (mx + mz > r2, my + mz > r2);
                let theta = bounds(
                    t.z_axis.z,
                    t.z_axis.x,
                    disc.x,
                    mean.x.atan2(mean.z),
                    narrow_x,
                );
                let phi = bounds(
                    t.z_axis.z,
                    t.z_axis.y,
                    disc.y,
                    mean.y.atan2(mean.z),
                    narrow_y,
                );
                let (f, c) = (cam.focal, cam.principal);
                let lo = Vec2::new(theta.x, phi.x);
                let hi = Vec2::new(theta.y, phi.y);
                let ahead = hi.max_element() < 1.5 && lo.min_element() > -1.5;
                let (pin_lo, pin_hi) = (
                    f * Vec2::new(lo.x.tan(), lo.y.tan()) + c,
                    f * Vec2::new(hi.x.tan(), hi.y.tan()) + c,
                );
                let reach = (lambda2.sqrt() * scale.max_element() / mean.length())
                    .min(1.0)
                    .asin();
                let (fish_lo, fish_hi) = fisheye_box(cam, mean, reach);
                let (box_lo, box_hi) = if cam.is_equiangular() {
                    (f * lo + c - open, f * hi + c + open)
                } else if cam.is_kannala_brandt() {
                    (fish_lo, fish_hi)
                } else {
                    (
                        select(ahead, pin_lo, c - FAR),
                        select(ahead, pin_hi, c + FAR),
                    )
                };
                // The fisheye's cone bound covers everything once it reaches a half space.
                let whole = inside || (cam.is_kannala_brandt() && reach >= PI / 2.0);
                Frustum {
                    lo: select(whole, c - FAR, box_lo),
                    hi: select(whole, c + FAR, box_hi),
                    mean,
                    contour,
                    seen: mean.length() > NEAR && cam.can_project(mean),
                }
            }

            pub fn project(p: &Params, cam: &Camera) -> Projected<Cull, Shade> {
                let rot = blocks::rotation_matrix(p.rotation);
                let scale = p.log_scale.exp();
                let opacity = sigmoid(p.opacity_logit);
                // λ-contour: where exp(-λ²/2) opacity = ALPHA_MIN.
                let lambda2 = 2.0 * (opacity / ALPHA_MIN).ln().max(0.0);
                let first = frustum(p, rot, scale, lambda2, cam.rotation, cam.translation, cam);
                let (mut lo, mut hi, mut seen) = (first.lo, first.hi, first.seen);
                if ROLLING_SHUTTER {
                    // The box holds the boxes seen from the first and the last row's pose.
                    let (rotation, translation) = (cam.rotation_at(1.0), cam.translation_at(1.0));
                    let last = frustum(p, rot, scale, lambda2, rotation, translation, cam);
                    lo = lo.min(last.lo);
                    hi = hi.max(last.hi);
                    seen = seen && last.seen;
                }
                let whiten = Mat3::from_diagonal(Vec3::ONE / scale) * rot.transpose();
                // A point x of the contour is at Q(t) x - t R shift at time t, Q(t) a turn by at
                // most t |shutter_turn| radians: it moves by at most t (|turn| |x| + |shift|).
                let mut motion = 0.0;
                if ROLLING_SHUTTER {
                    let reach = first.mean.length() + lambda2.sqrt() * scale.max_element();
                    motion = cam.shutter_turn.length() * reach + cam.shutter_shift.length();
                }
                Projected {
                    visible: seen && opacity >= ALPHA_MIN,
                    depth: first.mean.length(),
                    bbox_min: lo,
                    bbox_max: hi,
                    cull: Cull {
                        mean: first.mean,
                        contour: first.contour,
                        focal: cam.focal,
                        principal: cam.principal,
                        edges: select(
                            cam.is_kannala_brandt(),
                            1.0,
                            select(cam.is_equiangular(), 2.0, 0.0),
                        ),
                        motion,
                        rows: cam.size.y,
                    },
                    shade: Shade {
                        origin: whiten * (cam.center() - p.mean),
                        whiten,
                        opacity,
                        color: (spherical_harmonics(p.sh, p.mean - cam.center()) + 0.5)
                            .max(Vec3::ZERO),
                    },
                }
            }

            /// Whether the contour, grown by `grow`, reaches the side of the plane through the
            /// camera with unit normal `n` that the tile is on.
            fn reaches(n: Vec3, c: &Cull, grow: f32) -> bool {
                n.dot(c.mean) + n.dot(c.contour * n).max(0.0).sqrt() + grow >= 0.0
            }

            /// The PBF-CSF test: the tile's rays lie between the planes through the camera at its
            /// edges' horizontal and vertical angles; keep the tile unless the contour is wholly
            /// outside one of them (with a rolling shutter, grown by its motion until the tile's
            /// last row).
            pub fn tile_cull(tile: &Tile, c: &Cull) -> bool {
                let mut grow = 0.0;
                if ROLLING_SHUTTER {
                    grow = c.motion * (tile.max.y / c.rows).min(1.0);
                }
                let lo = (tile.min - c.principal) / c.focal;
                let hi = (tile.max - c.principal) / c.focal;
                let linear = c.edges == 2.0;
                let (l, r) = (
                    select(linear, lo.x, lo.x.atan()),
                    select(linear, hi.x, hi.x.atan()),
                );
                let (t, b) = (
                    select(linear, lo.y, lo.y.atan()),
                    select(linear, hi.y, hi.y.atan()),
                );
                c.edges == 1.0
                    || reaches(Vec3::new(l.cos(), 0.0, -l.sin()), c, grow)
                        && reaches(Vec3::new(-r.cos(), 0.0, r.sin()), c, grow)
                        && reaches(Vec3::new(0.0, t.cos(), -t.sin()), c, grow)
                        && reaches(Vec3::new(0.0, -b.cos(), b.sin()), c, grow)
            }

            pub fn pixel_info(pixel: Vec2, cam: &Camera) -> Ray {
                let mut rotation = cam.rotation;
                let mut shift = Vec3::ZERO;
                if ROLLING_SHUTTER {
                    let t = cam.shutter_time(pixel);
                    rotation = cam.rotation_at(t);
                    shift = cam.shutter_shift * t;
                }
                Ray {
                    dir: rotation.transpose() * cam.pixel_ray(pixel),
                    shift,
                }
            }

            /// Φ(s), the standard normal CDF (Abramowitz-Stegun 7.1.26, error below 1.5e-7).
            fn normal_cdf(s: f32) -> f32 {
                let x = s.abs() * 0.70710678;
                let t = 1.0 / (1.0 + 0.3275911 * x);
                let poly = t
                    * (0.254829592
                        + t * (-0.284496736
                            + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))));
                let tail = 0.5 * poly * (-x * x).exp();
                select(s >= 0.0, 1.0 - tail, tail)
            }

            pub fn evaluate(ray: Ray, s: &Shade) -> Contribution<Vec3> {
                let mut origin = s.origin;
                if ROLLING_SHUTTER {
                    origin += s.whiten * ray.shift;
                }
                let d = s.whiten * ray.dir;
                let m = origin.cross(d);
                let d2 = m.dot(m) / d.dot(d);
                let ahead = -origin.dot(d) / d.length();
                let alpha = (s.opacity * (-0.5 * d2).exp() * normal_cdf(ahead)).min(0.99);
                Contribution {
                    alpha,
                    color: s.color,
                    valid: alpha >= ALPHA_MIN,
                }
            }
        }
    };
}

exact!(geer, sh_coefficients = 16, rolling_shutter = false);
exact!(geer_sh0, sh_coefficients = 1, rolling_shutter = false);
exact!(geer_sh1, sh_coefficients = 4, rolling_shutter = false);
exact!(geer_sh2, sh_coefficients = 9, rolling_shutter = false);
exact!(geer_rs, sh_coefficients = 16, rolling_shutter = true);
