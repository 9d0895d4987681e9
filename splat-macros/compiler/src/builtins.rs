//! Functions every module can call: the methods of the built-in `Camera` and
//! `spherical_harmonics`, written in the accepted subset itself so they lower, differentiate
//! and emit (Rust, lanes, WGSL) like user code.
//!
//! The camera models come from the `splat-cameras` crate, whose `camera_models!` the runtime
//! expands as plain Rust and whose text this reads: one module per model with its `CODE`,
//! `NAME` and functions. Each model's
//! functions become builtins named `__{model}_{function}`, and `cam.project_point(p)` lowers to
//! a helper that picks the model by its code; a kernel specialized to one model
//! (`Kernel::models`) keeps only that model's branch. `spherical_harmonics` has its plain-Rust
//! twin in the runtime's prelude; the tests keep the two equal.

use quote::{format_ident, quote};

/// The items of `splat_cameras::camera_models!`: the camera models, shared with the runtime.
fn camera_source() -> Vec<syn::Item> {
    let file: syn::File = syn::parse_str(splat_cameras::SOURCE).expect("splat-cameras parses");
    let body = file
        .items
        .into_iter()
        .find_map(|item| match item {
            syn::Item::Macro(m) if m.ident.as_ref().is_some_and(|i| i == "camera_models") => {
                Some(m.mac.tokens)
            }
            _ => None,
        })
        .expect("splat-cameras defines camera_models!");
    // `() => { ITEMS };`: the one arm's body.
    let arm = body
        .into_iter()
        .find_map(|t| match t {
            proc_macro2::TokenTree::Group(g) if g.delimiter() == proc_macro2::Delimiter::Brace => {
                Some(g.stream())
            }
            _ => None,
        })
        .expect("camera_models! has a body");
    syn::parse2::<syn::File>(arm)
        .expect("camera_models!'s body is items")
        .items
}

/// The functions every camera model defines: `cam.{name}(..)` in a kernel.
const MODEL_FUNCTIONS: &[&str] = &["project_point", "pixel_ray", "can_project"];

/// A camera model of `splat-cameras`.
pub struct CameraModel {
    /// Its module name (`pinhole`), as in camera files and `CameraModel::name`.
    pub name: String,
    /// Its `CODE`, the camera's `model` word.
    pub code: u32,
    fns: Vec<syn::ItemFn>,
}

/// The camera models, in the order `splat-cameras` defines them.
pub fn camera_models() -> Vec<CameraModel> {
    camera_source()
        .into_iter()
        .filter_map(|item| match item {
            syn::Item::Mod(m) => Some(m),
            _ => None,
        })
        .map(|m| {
            let items = m.content.map(|(_, items)| items).unwrap_or_default();
            let code = items.iter().find_map(|item| match item {
                syn::Item::Const(c) if c.ident == "CODE" => match &*c.expr {
                    syn::Expr::Lit(syn::ExprLit {
                        lit: syn::Lit::Int(i),
                        ..
                    }) => i.base10_parse().ok(),
                    _ => None,
                },
                _ => None,
            });
            let fns = items
                .into_iter()
                .filter_map(|item| match item {
                    syn::Item::Fn(f) => Some(f),
                    _ => None,
                })
                .collect();
            CameraModel {
                name: m.ident.to_string(),
                code: code.expect("every camera model has an integer `CODE`"),
                fns,
            }
        })
        .collect()
}

/// The functions of `splat-cameras` outside the models' modules: they hold for every model
/// (`center`, the rolling shutter's pose), and `cam.{name}(..)` calls them.
fn shared_camera_fns() -> Vec<syn::ItemFn> {
    camera_source()
        .into_iter()
        .filter_map(|item| match item {
            syn::Item::Fn(f) => Some(f),
            _ => None,
        })
        .collect()
}

/// The builtin helper a `Camera` method call `cam.{method}(..)` lowers to, if it is one:
/// a model function, a shared camera function, or `is_{model}` (whether the camera is of
/// that model).
pub fn camera_helper(method: &str) -> Option<String> {
    let known = MODEL_FUNCTIONS.contains(&method)
        || shared_camera_fns().iter().any(|f| f.sig.ident == method)
        || method
            .strip_prefix("is_")
            .is_some_and(|m| camera_models().iter().any(|c| c.name == m));
    known.then(|| format!("__camera_{method}"))
}

/// Camera methods that read the camera model: a kernel calling them works with every model.
pub fn model_aware(method: &str) -> bool {
    MODEL_FUNCTIONS.contains(&method) || method.starts_with("is_")
}

/// Camera methods that read the rolling shutter: a kernel calling them models it.
pub fn shutter_aware(method: &str) -> bool {
    matches!(method, "shutter_time" | "rotation_at" | "translation_at")
}

/// Coefficient counts `spherical_harmonics` accepts: degrees 0 to 3.
pub const SH_COEFFICIENTS: &[usize] = &[1, 4, 9, 16];

/// The helper `spherical_harmonics(sh: [Vec3; n], dir)` lowers to.
pub fn sh_helper(n: usize) -> String {
    format!("__spherical_harmonics_{n}")
}

/// The camera builtins: every model's functions (renamed `__{model}_{function}`), the
/// `__camera_{function}` helpers choosing among them by the model's code, `__camera_is_{model}`
/// and the shared functions (renamed `__camera_{function}`).
fn camera_items() -> Vec<syn::ItemFn> {
    let models = camera_models();
    let mut out = vec![];
    for function in MODEL_FUNCTIONS {
        let mut sig = None;
        for m in &models {
            let mut f = m
                .fns
                .iter()
                .find(|f| f.sig.ident == function)
                .unwrap_or_else(|| panic!("camera model `{}` has no `{function}`", m.name))
                .clone();
            f.sig.ident = format_ident!("__{}_{function}", m.name);
            sig.get_or_insert_with(|| f.sig.clone());
            out.push(f);
        }
        let sig = sig.expect("at least one camera model");
        let args: Vec<syn::Ident> = sig
            .inputs
            .iter()
            .filter_map(|a| match a {
                syn::FnArg::Typed(t) => match &*t.pat {
                    syn::Pat::Ident(i) => Some(format_ident!(
                        "{}",
                        i.ident.to_string().trim_start_matches('_')
                    )),
                    _ => None,
                },
                _ => None,
            })
            .collect();
        let params = sig.inputs.iter().zip(&args).map(|(p, a)| match p {
            syn::FnArg::Typed(t) => {
                let ty = &t.ty;
                quote!(#a: #ty)
            }
            other => quote!(#other),
        });
        let ret = &sig.output;
        // The last model is the `else` of the chain.
        let mut chain = {
            let last = models.last().expect("a model");
            let f = format_ident!("__{}_{function}", last.name);
            quote!(#f(#(#args),*))
        };
        for m in models.iter().rev().skip(1) {
            let (f, code) = (format_ident!("__{}_{function}", m.name), m.code);
            chain = quote!(if cam.model == #code { #f(#(#args),*) } else { #chain });
        }
        let name = format_ident!("__camera_{function}");
        out.push(syn::parse_quote!(fn #name(#(#params),*) #ret { #chain }));
    }
    for m in &models {
        let (name, code) = (format_ident!("__camera_is_{}", m.name), m.code);
        out.push(syn::parse_quote!(fn #name(cam: &Camera) -> bool { cam.model == #code }));
    }
    for mut f in shared_camera_fns() {
        f.sig.ident = format_ident!("__camera_{}", f.sig.ident);
        out.push(f);
    }
    out
}

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

/// The builtin helpers' source, which every module parses like its own functions.
pub fn builtin_items() -> Vec<syn::ItemFn> {
    let source: String = SH_COEFFICIENTS.iter().map(|n| sh_source(*n)).collect();
    let file: syn::File = syn::parse_str(&source).expect("the builtin source parses");
    let sh = file.items.into_iter().filter_map(|item| match item {
        syn::Item::Fn(f) => Some(f),
        _ => None,
    });
    camera_items().into_iter().chain(sh).collect()
}
