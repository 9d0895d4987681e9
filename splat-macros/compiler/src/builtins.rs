//! Functions every module can call: the methods of the built-in `Camera` and
//! `spherical_harmonics`, written in the accepted subset itself so they lower, differentiate
//! and emit (Rust, lanes, WGSL) like user code. Each camera model follows `CameraModel` in
//! `splat-runtime/src/types.rs`, whose plain-Rust twins of these functions (and of
//! `spherical_harmonics` in its prelude) the tests keep equal to the compiled ones.

use crate::diag::Diag;
use crate::model::FnDef;

/// The `Camera` methods a kernel may call: (method, builtin helper it lowers to).
pub const CAMERA_METHODS: &[(&str, &str)] = &[
    ("project_point", "__camera_project_point"),
    ("pixel_ray", "__camera_pixel_ray"),
    ("center", "__camera_center"),
    ("can_project", "__camera_can_project"),
];

/// Coefficient counts `spherical_harmonics` accepts: degrees 0 to 3.
pub const SH_COEFFICIENTS: &[usize] = &[1, 4, 9, 16];

/// The helper `spherical_harmonics(sh: [Vec3; n], dir)` lowers to.
pub fn sh_helper(n: usize) -> String {
    format!("__spherical_harmonics_{n}")
}

/// Methods that read the camera model: a kernel calling them works with every model.
pub const MODEL_AWARE: &[&str] = &["project_point", "pixel_ray"];

/// Model codes are `CameraModel as u32`: 0 pinhole, 1 Kannala-Brandt, 2 equiangular.
const SOURCE: &str = r#"
/// The pixel of a camera-space point under the camera's model.
fn __camera_project_point(cam: &Camera, p: Vec3) -> Vec2 {
    let (f, c) = (cam.focal, cam.principal);
    if cam.model == 1u32 {
        let rxy = (p.x * p.x + p.y * p.y).sqrt();
        let theta = rxy.atan2(p.z);
        let k = cam.distortion;
        let t2 = theta * theta;
        let r = theta * (1.0 + t2 * (k.x + t2 * (k.y + t2 * (k.z + t2 * k.w))));
        // r / rxy -> 1 / z on the optical axis.
        let scale = select(rxy > 1e-20, r / rxy, 1.0 / p.z);
        f * Vec2::new(p.x, p.y) * scale + c
    } else if cam.model == 2u32 {
        f * Vec2::new(p.x.atan2(p.z), p.y.atan2(p.z)) + c
    } else {
        f * Vec2::new(p.x, p.y) / p.z + c
    }
}

/// The camera-space unit direction through a pixel position.
fn __camera_pixel_ray(cam: &Camera, pixel: Vec2) -> Vec3 {
    let m = (pixel - cam.principal) / cam.focal;
    if cam.model == 1u32 {
        // Invert r(theta) by Newton's method from theta = r (KB_NEWTON_STEPS in the runtime).
        let r = m.length();
        let k = cam.distortion;
        let mut theta = r;
        for _step in 0..8 {
            let t2 = theta * theta;
            let value = theta * (1.0 + t2 * (k.x + t2 * (k.y + t2 * (k.z + t2 * k.w))));
            let slope = 1.0 + t2 * (3.0 * k.x + t2 * (5.0 * k.y + t2 * (7.0 * k.z + t2 * 9.0 * k.w)));
            // Past the polynomial's fold (a pixel no ray reaches) the steps would run off:
            // keep theta a direction.
            theta = (theta - (value - r) / slope).clamp(0.0, 3.14159265);
        }
        let dir = select(r > 1e-20, m / r, Vec2::ZERO);
        (dir * theta.sin()).extend(theta.cos())
    } else if cam.model == 2u32 {
        Vec3::new(m.x.sin() * m.y.cos(), m.x.cos() * m.y.sin(), m.x.cos() * m.y.cos()).normalize()
    } else {
        m.extend(1.0).normalize()
    }
}

/// Whether `project_point` maps the camera-space point `p` to a meaningful pixel: in front
/// of the image plane for pinhole and equiangular cameras; up to 172 degrees off axis for the
/// fisheye (the Kannala-Brandt polynomial folds back near 180).
fn __camera_can_project(cam: &Camera, p: Vec3) -> bool {
    if cam.model == 1u32 {
        (p.x * p.x + p.y * p.y).sqrt().atan2(p.z) < 3.0
    } else {
        p.z > 0.0
    }
}

/// The camera centre in world space.
fn __camera_center(cam: &Camera) -> Vec3 {
    -(cam.rotation.transpose() * cam.translation)
}
"#;

/// Real spherical harmonics up to degree 3 in direction `dir` (normalized here), summed with
/// the coefficients `sh` (one `Vec3` per basis function; the 3DGS constants and signs).
fn sh_source(n: usize) -> String {
    format!(
        r#"
fn {name}(sh: [Vec3; {n}], dir: Vec3) -> Vec3 {{
    let d = dir.normalize();
    let (x, y, z) = (d.x, d.y, d.z);
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let basis = [
        0.28209479177387814,
        -0.4886025119029199 * y,
        0.4886025119029199 * z,
        -0.4886025119029199 * x,
        1.0925484305920792 * x * y,
        -1.0925484305920792 * y * z,
        0.31539156525252005 * (2.0 * zz - xx - yy),
        -1.0925484305920792 * x * z,
        0.5462742152960396 * (xx - yy),
        -0.5900435899266435 * y * (3.0 * xx - yy),
        2.890611442640554 * x * y * z,
        -0.4570457994644658 * y * (4.0 * zz - xx - yy),
        0.3731763325901154 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy),
        -0.4570457994644658 * x * (4.0 * zz - xx - yy),
        1.445305721320277 * z * (xx - yy),
        -0.5900435899266435 * x * (xx - 3.0 * yy),
    ];
    let mut c = Vec3::ZERO;
    for i in 0..{n} {{
        c += sh[i] * basis[i];
    }}
    c
}}
"#,
        name = sh_helper(n)
    )
}

/// The builtin helpers, parsed like a module's own functions.
pub fn builtin_fns(mut parse: impl FnMut(syn::ItemFn) -> Option<FnDef>, diag: &Diag) -> Vec<FnDef> {
    let mut source = SOURCE.to_string();
    for n in SH_COEFFICIENTS {
        source += &sh_source(*n);
    }
    let file: syn::File = syn::parse_str(&source).expect("the builtin source parses");
    let errors_before = diag.messages().len();
    let fns: Vec<FnDef> = file
        .items
        .into_iter()
        .filter_map(|item| match item {
            syn::Item::Fn(f) => parse(f),
            _ => None,
        })
        .collect();
    debug_assert_eq!(
        diag.messages().len(),
        errors_before,
        "the builtin source type-checks"
    );
    fns
}
