//! The source-level types of the accepted subset, their flattening into IR scalars, and the
//! built-in structs shared with splat-runtime.

use crate::ir::Scalar;
use proc_macro2::TokenStream;
use quote::quote;
use std::rc::Rc;

#[derive(Clone, Debug, PartialEq)]
pub enum Ty {
    F32,
    Bool,
    U32,
    I32,
    /// Compile-time integers: loop counters, array lengths, unsuffixed integer literals.
    /// Never reaches the IR as a runtime value.
    Index,
    /// `Vec2`, `Vec3`, `Vec4`.
    Vec(usize),
    /// `Mat2`, `Mat3` (column-major, like glam).
    Mat(usize),
    /// `Quat`, stored (x, y, z, w) like glam.
    Quat,
    Array(Box<Ty>, usize),
    Struct(Rc<StructTy>),
    Tuple(Vec<Ty>),
    /// The type of an expression that already failed to type-check (suppresses cascades).
    Error,
}

#[derive(Debug, PartialEq)]
pub struct StructTy {
    /// The name as written, e.g. `Shade` or `Projected<Cull, Shade>`.
    pub display: String,
    /// How emitted code names the type.
    pub path: TokenStreamEq,
    pub fields: Vec<(String, Ty)>,
}

/// A token stream compared by its text, so types can derive `PartialEq`.
#[derive(Clone, Debug)]
pub struct TokenStreamEq(pub TokenStream);
impl PartialEq for TokenStreamEq {
    fn eq(&self, other: &Self) -> bool {
        self.0.to_string() == other.0.to_string()
    }
}

impl Ty {
    /// The source type of an IR scalar.
    pub fn scalar(s: Scalar) -> Ty {
        match s {
            Scalar::F32 => Ty::F32,
            Scalar::U32 => Ty::U32,
            Scalar::I32 => Ty::I32,
            Scalar::Bool => Ty::Bool,
        }
    }

    /// The IR scalars this type flattens to, in order.
    pub fn slots(&self) -> Vec<Scalar> {
        let mut out = vec![];
        self.push_slots(&mut out);
        out
    }

    fn push_slots(&self, out: &mut Vec<Scalar>) {
        match self {
            Ty::F32 => out.push(Scalar::F32),
            Ty::Bool => out.push(Scalar::Bool),
            Ty::U32 => out.push(Scalar::U32),
            Ty::I32 => out.push(Scalar::I32),
            Ty::Index => out.push(Scalar::U32),
            Ty::Vec(n) => out.extend(std::iter::repeat_n(Scalar::F32, *n)),
            Ty::Mat(n) => out.extend(std::iter::repeat_n(Scalar::F32, n * n)),
            Ty::Quat => out.extend([Scalar::F32; 4]),
            Ty::Array(t, n) => (0..*n).for_each(|_| t.push_slots(out)),
            Ty::Struct(s) => s.fields.iter().for_each(|(_, t)| t.push_slots(out)),
            Ty::Tuple(ts) => ts.iter().for_each(|t| t.push_slots(out)),
            Ty::Error => {}
        }
    }

    pub fn slot_count(&self) -> usize {
        self.slots().len()
    }

    pub fn contains_index(&self) -> bool {
        match self {
            Ty::Index => true,
            Ty::Array(t, _) => t.contains_index(),
            Ty::Struct(s) => s.fields.iter().any(|(_, t)| t.contains_index()),
            Ty::Tuple(ts) => ts.iter().any(Ty::contains_index),
            _ => false,
        }
    }

    pub fn is_float_scalar(&self) -> bool {
        matches!(self, Ty::F32)
    }

    /// True where every slot is an `f32` (vectors, matrices, float arrays and structs).
    pub fn all_float(&self) -> bool {
        self.slots().iter().all(|s| *s == Scalar::F32)
    }

    /// Readable names of the slots relative to a value called `base`, e.g. `s_center_x`.
    pub fn slot_names(&self, base: &str) -> Vec<String> {
        let mut out = vec![];
        self.push_names(base, &mut out);
        out
    }

    fn push_names(&self, base: &str, out: &mut Vec<String>) {
        let join = |a: &str, b: &str| {
            if a.is_empty() {
                b.to_string()
            } else {
                format!("{a}_{b}")
            }
        };
        match self {
            Ty::Vec(_) | Ty::Quat => {
                let n = if let Ty::Vec(n) = self { *n } else { 4 };
                for c in ["x", "y", "z", "w"].iter().take(n) {
                    out.push(join(base, c));
                }
            }
            Ty::Mat(n) => {
                for c in 0..*n {
                    for r in 0..*n {
                        out.push(join(base, &format!("{c}{r}")));
                    }
                }
            }
            Ty::Array(t, n) => (0..*n).for_each(|i| t.push_names(&join(base, &i.to_string()), out)),
            Ty::Struct(s) => s
                .fields
                .iter()
                .for_each(|(f, t)| t.push_names(&join(base, f), out)),
            Ty::Tuple(ts) => ts
                .iter()
                .enumerate()
                .for_each(|(i, t)| t.push_names(&join(base, &i.to_string()), out)),
            _ => out.push(if base.is_empty() {
                "t".into()
            } else {
                base.into()
            }),
        }
    }

    /// How emitted Rust names this type (f32 flavor).
    pub fn rust(&self) -> TokenStream {
        match self {
            Ty::F32 => quote!(f32),
            Ty::Bool => quote!(bool),
            Ty::U32 => quote!(u32),
            Ty::I32 => quote!(i32),
            Ty::Index => quote!(usize),
            Ty::Vec(2) => quote!(::splat_runtime::glam::Vec2),
            Ty::Vec(3) => quote!(::splat_runtime::glam::Vec3),
            Ty::Vec(_) => quote!(::splat_runtime::glam::Vec4),
            Ty::Mat(2) => quote!(::splat_runtime::glam::Mat2),
            Ty::Mat(_) => quote!(::splat_runtime::glam::Mat3),
            Ty::Quat => quote!(::splat_runtime::glam::Quat),
            Ty::Array(t, n) => {
                let t = t.rust();
                quote!([#t; #n])
            }
            Ty::Struct(s) => s.path.0.clone(),
            Ty::Tuple(ts) => {
                let ts = ts.iter().map(Ty::rust);
                quote!((#(#ts,)*))
            }
            Ty::Error => quote!(()),
        }
    }
}

impl std::fmt::Display for Ty {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Ty::F32 => write!(f, "f32"),
            Ty::Bool => write!(f, "bool"),
            Ty::U32 => write!(f, "u32"),
            Ty::I32 => write!(f, "i32"),
            Ty::Index => write!(f, "integer"),
            Ty::Vec(n) => write!(f, "Vec{n}"),
            Ty::Mat(n) => write!(f, "Mat{n}"),
            Ty::Quat => write!(f, "Quat"),
            Ty::Array(t, n) => write!(f, "[{t}; {n}]"),
            Ty::Struct(s) => write!(f, "{}", s.display),
            Ty::Tuple(ts) => {
                let s: Vec<String> = ts.iter().map(|t| t.to_string()).collect();
                write!(f, "({})", s.join(", "))
            }
            Ty::Error => write!(f, "{{error}}"),
        }
    }
}

/// A `u32` field of a built-in struct that the runtime stores as a `#[repr(u32)]` enum with
/// `from_code` (`Camera::model`): the enum's path, for reading (`as u32`) and building it.
pub fn builtin_enum_field(s: &StructTy, field: &str) -> Option<TokenStream> {
    (s.display == "Camera" && field == "model").then(|| quote!(::splat_runtime::CameraModel))
}

/// Whether `ty` is the built-in `Camera`.
pub fn is_camera(ty: &Ty) -> bool {
    matches!(ty, Ty::Struct(s) if s.display == "Camera")
}

/// The names of the built-in generic structs and their parameters.
pub const BUILTIN_STRUCTS: &[&str] = &["Camera", "Tile", "Projected", "Contribution"];

/// A built-in struct that takes no type arguments (`Camera`, `Tile`).
pub fn plain_builtin(name: &str) -> Ty {
    builtin_struct(name, &[])
        .expect("a built-in struct")
        .expect("without type arguments")
}

/// Instantiates a built-in struct of splat-runtime (`types.rs` there) with type arguments.
/// Returns `None` for an unknown name; the caller checks the argument count.
pub fn builtin_struct(name: &str, args: &[Ty]) -> Option<Result<Ty, String>> {
    let v2 = Ty::Vec(2);
    let (params, fields): (usize, Vec<(&str, Ty)>) = match name {
        "Camera" => (
            0,
            vec![
                ("rotation", Ty::Mat(3)),
                ("translation", Ty::Vec(3)),
                ("focal", v2.clone()),
                ("principal", v2.clone()),
                ("size", v2.clone()),
                ("distortion", Ty::Vec(4)),
                ("shutter_turn", Ty::Vec(3)),
                ("shutter_shift", Ty::Vec(3)),
                // `CameraModel as u32`, last so the float slots are the leading words.
                ("model", Ty::U32),
            ],
        ),
        "Tile" => (0, vec![("min", v2.clone()), ("max", v2.clone())]),
        "Projected" if args.len() == 2 => (
            2,
            vec![
                ("visible", Ty::Bool),
                ("depth", Ty::F32),
                ("bbox_min", v2.clone()),
                ("bbox_max", v2.clone()),
                ("cull", args[0].clone()),
                ("shade", args[1].clone()),
            ],
        ),
        "Projected" => (2, vec![]),
        "Contribution" if args.len() == 1 => (
            1,
            vec![
                ("alpha", Ty::F32),
                ("color", args[0].clone()),
                ("valid", Ty::Bool),
            ],
        ),
        "Contribution" => (1, vec![]),
        _ => return None,
    };
    if args.len() != params {
        return Some(Err(format!(
            "`{name}` takes {params} type argument(s), found {}",
            args.len()
        )));
    }
    let ident = proc_macro2::Ident::new(name, proc_macro2::Span::call_site());
    let (display, path) = if args.is_empty() {
        (name.to_string(), quote!(::splat_runtime::#ident))
    } else {
        let shown: Vec<String> = args.iter().map(|a| a.to_string()).collect();
        let rust = args.iter().map(Ty::rust);
        (
            format!("{name}<{}>", shown.join(", ")),
            quote!(::splat_runtime::#ident<#(#rust),*>),
        )
    };
    let fields = fields
        .into_iter()
        .map(|(n, t)| (n.to_string(), t))
        .collect();
    Some(Ok(Ty::Struct(Rc::new(StructTy {
        display,
        path: TokenStreamEq(path),
        fields,
    }))))
}
