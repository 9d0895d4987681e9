//! The compiler-test corpus: annotated functions that together use every operator, every
//! intrinsic, branches (nested, as statements and as expressions), constant loops (carrying
//! scalar, vector and array state, nested, followed by more code), helper calls, custom
//! adjoints, structs, tuples, matrices and quaternions. `tests/corpus.rs` checks each against
//! finite differences and compares its lane and scalar forms; `tests/plain.rs` compares what the
//! compiler emits with the same source compiled by rustc alone ([`plain`]).

use splat_macros::splat_functions;

/// The corpus' source (all but `jacobians`, whose `jacobian` is the compiler's alone): given
/// `#[splat_functions]` below, and nothing in [`plain`].
macro_rules! corpus_source {
    ($(#[$compiler:meta])?) => {
        $(#[$compiler])?
        pub mod scalars {
            use splat_runtime::prelude::*;

            /// Every arithmetic operator.
            pub fn arith(x: f32, y: f32) -> f32 {
                let a = x * x + 3.0 * y - -x;
                let b = a / (1.0 + y * y);
                b % 2.5 - x
            }

            /// exp, ln, ln_1p, sqrt, rsqrt, recip (free and method forms).
            pub fn transcendental(x: f32, y: f32) -> f32 {
                let a = x.exp() + ln(y) + y.ln_1p() * exp(0.5 * x);
                let b = x.sqrt() + rsqrt(y) + y.recip() + log(x) + log1p(x) + sqrt(y);
                a * b
            }

            /// Trigonometry, including atan2 (its two forms weighted apart, so that swapped operands
        /// change the sum) and the inverse functions.
            pub fn trig(x: f32, y: f32) -> f32 {
                let a = x.sin() * y.cos() + tan(x) + sin(y) * cos(x);
                let b = x.asin() + y.acos() * 0.5 + x.atan() + y.atan2(x) + 0.5 * atan2(x, y);
                a + b * x.tanh()
            }

            /// Powers and fused forms.
            pub fn powers(x: f32, y: f32) -> f32 {
                x.powf(y) + x.powi(3) + y.powi(-2) + x.mul_add(y, 1.0) + x.hypot(y) + x.powi(0)
            }

            /// min, max, clamp, abs as methods and free functions.
            pub fn minmax(x: f32, y: f32, z: f32) -> f32 {
                let a = x.min(y) + max(y, z) + z.clamp(x, y) + clamp(x, -0.5, 0.5);
                a * (x - y).abs() + abs(z) + min(x, z) * f32::max(x, z)
            }

            /// Piecewise-constant and piecewise-linear functions: floor, ceil, round, trunc, fract, signum.
            pub fn rounding(x: f32) -> f32 {
                let k = x.floor() + x.ceil() * 2.0 + x.round() + x.trunc() + x.signum();
                k * 0.1 + x.fract() * x
            }

            /// sigmoid, erf, log2, log10, unit conversions, constants.
            pub fn misc(x: f32, y: f32) -> f32 {
                let s = sigmoid(x) * sigmoid(-3.0 * y) + erf(x - 1.0) * y;
                s + x.log2() * y.log10()
                    + x.to_radians()
                    + y.to_degrees() * core::f32::consts::PI
                    + f32::EPSILON * std::f32::consts::E
            }

            /// sin_cos returns a tuple; tuples destructure.
            pub fn sincos(x: f32) -> (f32, f32) {
                let (s, c) = x.sin_cos();
                (s * c, s + c * x)
            }
        }

        $(#[$compiler])?
        pub mod vectors {
            use splat_runtime::prelude::*;

            /// cross, normalize, dot, length with free and method forms.
            pub fn geometry(a: Vec3, b: Vec3) -> Vec3 {
                let c = cross(a, b);
                normalize(c) * dot(a, b) + a.normalize_or_zero() * b.length() + c * length(a)
            }

            /// Element-wise methods and vector-scalar broadcasting.
            pub fn elementwise(a: Vec4, b: Vec4, t: f32) -> Vec4 {
                let l = a.lerp(b, t);
                let m = a.min(b) + a.max(b) * 2.0 - a.abs() / 3.0;
                let e = (b * 0.25).exp() + a.recip() + b.powf(1.5);
                l * m + e + a.clamp(Vec4::splat(-0.5), Vec4::ONE) + 1.0 / (b + 1.0)
            }

            /// Swizzles, extend, truncate, distances and reductions.
            pub fn shape(a: Vec3, b: Vec2) -> Vec4 {
                let xy = a.xy() + b.yx();
                let v = xy.extend(a.z).extend(b.x);
                let w = v.truncate().zyx() * a.distance(Vec3::new(b.x, b.y, 1.0));
                let s = a.element_sum() + a.max_element() * a.min_element() + b.element_product();
                w.extend(s + a.distance_squared(Vec3::X) + b.length_squared())
            }

            /// Quaternion rotation three ways, and the Hamilton product.
            pub fn rotate(q: Quat, v: Vec3) -> Vec3 {
                let u = q.normalize();
                let m = Mat3::from_quat(u);
                let r = u * v + m * v * 0.5 + u.mul_vec3(v.yzx());
                let p = u * Quat::from_xyzw(0.1, 0.2, 0.3, 0.9) * u.conjugate();
                r + Vec3::new(p.x, p.y, p.z) * q.length() + Vec3::splat(q.dot(u))
            }

            /// Component access and assignment into vector fields.
            pub fn components(a: Vec3) -> Vec3 {
                let mut v = a;
                v.x = a.y * a.z;
                v[2] = v.x + a[0];
                v.y += v.z * 2.0;
                v
            }
        }

        $(#[$compiler])?
        pub mod matrices {
            use splat_runtime::prelude::*;

            /// Mat3: product with vectors and matrices, transpose, determinant, inverse.
            pub fn mat3(m: Mat3, v: Vec3) -> Vec3 {
                let n = m.transpose() * m + Mat3::IDENTITY;
                let w = n.inverse() * v;
                w * m.determinant() + m.mul_vec3(v) + m.col(1) * m.row(2).x + m.z_axis
            }

            /// Mat2: inverse, determinant, constructors, scaling.
            pub fn mat2(a: Vec2, b: Vec2, s: f32) -> Mat2 {
                let m = Mat2::from_cols(a, b);
                let d = Mat2::from_diagonal(Vec2::new(s, s * s));
                let i = inverse(m) * 2.0;
                i * d + transpose(m) * determinant(m) - m.mul_mat2(&d) + m.mul_scalar(0.5)
            }

            /// The EWA covariance chain of 3DGS: rotation from a quaternion, scale, J Sigma J^T.
            pub fn covariance(rot: Vec4, log_scale: Vec3, t: Vec3) -> Vec3 {
                let q = Quat::from_xyzw(rot.y, rot.z, rot.w, rot.x).normalize();
                let r = Mat3::from_quat(q);
                let s = Mat3::from_diagonal(log_scale.exp());
                let m = r * s;
                let sigma = m * m.transpose();
                let z = t.z;
                let j = Mat3::from_cols(
                    Vec3::new(1.0 / z, 0.0, 0.0),
                    Vec3::new(0.0, 1.0 / z, 0.0),
                    Vec3::new(-t.x / (z * z), -t.y / (z * z), 0.0),
                );
                let c = j * sigma * j.transpose();
                Vec3::new(c.x_axis.x + 0.3, c.y_axis.x, c.y_axis.y + 0.3)
            }
        }

        $(#[$compiler])?
        pub mod control {
            use splat_runtime::prelude::*;

            /// Nested if / else-if / else as expressions.
            pub fn nested(x: f32, y: f32) -> f32 {
                if x > 0.0 {
                    if y > 0.0 { x * y } else { x - y * y }
                } else if y > 1.0 {
                    (x * y).exp()
                } else {
                    let t = x + y;
                    t * t * 0.5
                }
            }

            /// `if` as a statement assigning several variables, without and with `else`.
            pub fn statements(x: f32, y: f32) -> f32 {
                let mut a = x;
                let mut b = y;
                if x > y {
                    a = a * b;
                    b = b + 1.0;
                }
                if a > 0.5 {
                    b *= a;
                } else {
                    a -= b;
                }
                a * b + a
            }

            /// A loop carrying vector state, then code after it.
            pub fn vector_loop(v: Vec3, s: f32) -> Vec3 {
                let mut acc = Vec3::ZERO;
                let mut p = v;
                for i in 0..4 {
                    p = p * s + Vec3::new(1.0, 0.0, -1.0) * (i as f32);
                    acc += p.normalize() * (i + 1) as f32;
                }
                let n = acc.length();
                acc / n + p
            }

            /// Arrays written by a loop, nested loops, and a branch on the loop counter.
            pub fn array_loop(a: [f32; 4], x: f32) -> [f32; 4] {
                let mut out = [0.0; 4];
                for i in 0..4 {
                    let mut s = a[i];
                    for j in 0..=i {
                        s = s * x + a[j];
                    }
                    if i == 0 {
                        out[i] = s;
                    } else {
                        out[i] = s + out[i - 1] * 0.5;
                    }
                }
                out
            }

            /// select whose untaken side is NaN or infinite.
            pub fn guarded(x: f32, y: f32) -> f32 {
                let a = select(x > 0.0, x.ln() * y, -x);
                let b = select(y != 0.0, x / y, 0.0);
                let c = select(x > 1.0, (x - 1.0).sqrt(), 0.0);
                a + b + c
            }

            /// Branches on a bool and a u32 parameter; integer arithmetic and casts.
            pub fn flags(x: f32, on: bool, n: u32) -> f32 {
                let k = (n * 2u32 + 1) as f32;
                let m = if on { x * k } else { x / k };
                let bits = (n & 3) | (n << 1u32);
                select(bits > 4u32, m, m * m) + (n % 3u32) as f32 + (-(n as i32)) as f32
            }
        }

        $(#[$compiler])?
        pub mod structured {
            #[allow(unused_imports)]
            use splat_macros::adjoint;
            use splat_runtime::prelude::*;

            pub const SH_C0: f32 = 0.28209479177387814;
            pub const SH_C1: f32 = 0.4886025119029199;
            pub const SH_C2: [f32; 5] = [
                1.0925484305920792,
                -1.0925484305920792,
                0.31539156525252005,
                -1.0925484305920792,
                0.5462742152960396,
            ];
            pub const SH_C3: [f32; 7] = [
                -0.5900435899266435,
                2.890611442640554,
                -0.4570457994644658,
                0.3731763325901154,
                -0.4570457994644658,
                1.445305721320277,
                -0.5900435899266435,
            ];

            pub struct Gaussian {
                pub mean: Vec3,
                pub scale: Vec3,
                pub opacity: f32,
                pub sh: [Vec3; 16],
            }

            pub struct Splat {
                pub center: Vec2,
                pub color: Vec3,
                pub weights: [f32; 2],
                pub front: bool,
            }

            fn sq(x: f32) -> f32 {
                x * x
            }

            fn norm2(v: Vec3) -> f32 {
                sq(v.x) + sq(v.y) + sq(v.z)
            }

            /// Degree-3 spherical harmonics (the 3DGS color model), with module constants.
            pub fn sh_color(sh: [Vec3; 16], dir: Vec3) -> Vec3 {
                let d = dir.normalize();
                let (x, y, z) = (d.x, d.y, d.z);
                let (xx, yy, zz) = (x * x, y * y, z * z);
                let basis = [
                    SH_C0,
                    -SH_C1 * y,
                    SH_C1 * z,
                    -SH_C1 * x,
                    SH_C2[0] * x * y,
                    SH_C2[1] * y * z,
                    SH_C2[2] * (2.0 * zz - xx - yy),
                    SH_C2[3] * x * z,
                    SH_C2[4] * (xx - yy),
                    SH_C3[0] * y * (3.0 * xx - yy),
                    SH_C3[1] * x * y * z,
                    SH_C3[2] * y * (4.0 * zz - xx - yy),
                    SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy),
                    SH_C3[4] * x * (4.0 * zz - xx - yy),
                    SH_C3[5] * z * (xx - yy),
                    SH_C3[6] * x * (xx - 3.0 * yy),
                ];
                let mut c = Vec3::splat(0.5);
                for i in 0..16 {
                    c += sh[i] * basis[i];
                }
                c.max(Vec3::ZERO)
            }

            /// Struct in, struct out, helper calls, a bool field.
            pub fn splat_of(g: &Gaussian, eye: Vec3) -> Splat {
                let d = g.mean - eye;
                let r2 = norm2(d) + sq(g.scale.x);
                let color = sh_color(g.sh, d);
                Splat {
                    center: Vec2::new(d.x / d.z, d.y / d.z),
                    color: color * sigmoid(g.opacity),
                    weights: [r2.sqrt(), g.scale.length() / r2],
                    front: d.z > 0.0,
                }
            }

            /// A helper with a user-written adjoint: the compiler uses `soft_abs_adjoint` instead of
            /// differentiating the body.
            #[adjoint(soft_abs_adjoint)]
            fn soft_abs(x: f32, eps: f32) -> f32 {
                (x * x + eps * eps).sqrt() - eps
            }

            fn soft_abs_adjoint(x: f32, eps: f32, d_out: f32) -> (f32, f32) {
                let r = (x * x + eps * eps).sqrt();
                (d_out * x / r, d_out * (eps / r - 1.0))
            }

            pub fn uses_custom(x: f32, y: f32) -> f32 {
                soft_abs(x - y, 0.1) * y + soft_abs(y, 0.5)
            }

            /// no_diff stops the gradient: d/dx of the result is only through the first factor.
            pub fn stopped(x: f32, y: f32) -> f32 {
                x * no_diff(x * y) + (no_diff(x) as u32) as f32
            }
        }

        /// Functions evaluated exactly at their non-differentiable or singular points by
        /// `tests/kinks.rs`; each gradient there follows a documented rule and is finite.
        $(#[$compiler])?
        pub mod kinks {
            use splat_runtime::prelude::*;

            pub fn sqrt_of(x: f32) -> f32 {
                x.sqrt()
            }
            pub fn rsqrt_of(x: f32) -> f32 {
                rsqrt(x)
            }
            pub fn ln_of(x: f32) -> f32 {
                x.ln()
            }
            pub fn recip_of(x: f32) -> f32 {
                x.recip()
            }
            pub fn asin_of(x: f32) -> f32 {
                x.asin()
            }
            pub fn atan2_of(y: f32, x: f32) -> f32 {
                y.atan2(x)
            }
            pub fn length_of(v: Vec3) -> f32 {
                v.length()
            }
            pub fn normalize_of(v: Vec3) -> Vec3 {
                v.normalize()
            }
            pub fn max_of(x: f32, y: f32) -> f32 {
                x.max(y)
            }
            pub fn min_of(x: f32, y: f32) -> f32 {
                x.min(y)
            }
            pub fn clamp_of(x: f32) -> f32 {
                x.clamp(0.0, 1.0)
            }
            pub fn abs_of(x: f32) -> f32 {
                x.abs()
            }
            /// The division only happens on the side taken.
            pub fn lazy_div(x: f32, y: f32) -> f32 {
                select(y != 0.0, x / y, 0.0)
            }
            /// The division happens before the select (an infinite value is computed and discarded).
            pub fn eager_div(x: f32, y: f32) -> f32 {
                let q = x / y;
                select(y != 0.0, q, 0.0)
            }
            /// The untaken side is NaN (ln of a negative number).
            pub fn nan_branch(x: f32) -> f32 {
                if x > 0.0 { x.ln() * 2.0 } else { 0.5 * x }
            }
            /// The untaken side overflows to infinity.
            pub fn inf_branch(x: f32) -> f32 {
                select(x < 40.0, (x * 3.0).exp(), x)
            }
        }
    };
}

corpus_source!(#[splat_functions]);

/// The same source as ordinary Rust, compiled by rustc with the prelude's plain intrinsics:
/// what the compiler's kernels must compute. (Written to use every form the compiler reads,
/// `a = a * b` beside `b *= a`, and the SH constants to f64's digits, not as Clippy would.)
#[allow(clippy::assign_op_pattern, clippy::excessive_precision)]
pub mod plain {
    corpus_source!();
}

/// Forward mode inside a kernel: `jacobian` of a map that uses every differentiable operation
/// (branches, selects and kinks included). `tests/jacobians.rs` checks the Jacobian against
/// central differences of the map's f64 twin; the corpus' gradient test checks its adjoint
/// (reverse over forward) against differences of the Jacobian: second differences.
#[splat_functions]
pub mod jacobians {
    use splat_runtime::prelude::*;

    pub fn every_op(p: Vec2) -> Vec4 {
        let (x, y) = (p.x, p.y);
        let a = x * y + x / (1.0 + y * y) - y % 0.7 + x.exp() + y.ln() + x.ln_1p();
        let b = x.sqrt() + rsqrt(y) + y.recip() + (x - 0.5).abs() + x.min(y) + x.max(0.2 * y);
        let c = x.sin() * y.cos() + x.tan() + y.tanh() + x.asin() + y.acos() + x.atan();
        let d = x.powf(y) + y.powi(3) + x.fract() * x.floor() + sigmoid(x - y) + y.atan2(x);
        let d = d + erf(x - y);
        let e = if x > y { x * x } else { y.sqrt() * x };
        Vec4::new(a, b + e, c, select(x > 0.3, d, -d))
    }

    pub fn every_op_jacobian(x: f32, y: f32) -> (Vec2, Vec2, Vec2, Vec2) {
        let (_, j) = jacobian(|p| every_op(p), Vec2::new(x, y));
        (j[0], j[1], j[2], j[3])
    }

    /// A branch whose sides do not depend on the point (its tangent is zero in every
    /// direction) beside one whose do.
    pub fn branch_jacobian(x: f32, y: f32) -> Vec4 {
        let (v, j) = jacobian(
            |p: Vec2| {
                let step = if p.x > 0.5 { 1.0 } else { -1.0 };
                let bend = if p.y > 0.5 { p.x * p.y } else { p.y - p.x };
                Vec2::new(step, bend * step)
            },
            Vec2::new(x, y),
        );
        Vec4::new(v.x + v.y, j[0].x + j[0].y, j[1].x, j[1].y)
    }

    /// The value and the Jacobian together, of a map from a scalar, at a point the map reads
    /// twice (the copies keep one direction per input).
    pub fn scalar_jacobian(t: f32) -> Vec4 {
        let (v, j) = jacobian(|s: f32| Vec3::new(s * s, s.sin(), t * s.exp()), t);
        Vec4::new(v.x, v.y + v.z, j[0], j[1] + j[2])
    }
}
