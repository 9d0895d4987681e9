//! The signature stage, between parsing and lowering (as serde_derive's `check.rs`): what the
//! module promises at its boundaries is checked before any body is lowered, and only a
//! [`Checked`] model is handed on. For a method, its role functions against the runtime's
//! contract (`project`, `tile_cull`, `pixel_info`, `evaluate`), with the types they fix; for
//! every helper with `#[adjoint(f)]`, `f`'s signature. Errors are about signatures, so they
//! point at them, and a module that fails here is not lowered (its bodies' errors follow once
//! its signatures are right). The bodies are checked next, by `typeck`.

use crate::Kind;
use crate::diag::{Diag, edit_distance};
use crate::model::{FnDef, Module};
use crate::types::{Ty, plain_builtin};

/// A module whose signatures were checked.
pub struct Checked<'m> {
    pub module: &'m Module,
    /// Each helper with `#[adjoint(f)]`, with `f`.
    pub adjoints: Vec<(&'m FnDef, &'m FnDef)>,
    /// For a `#[splat_method]`: its role functions and the types they fix.
    pub roles: Option<Roles<'m>>,
}

/// A method's role functions and the types its signatures fix.
pub struct Roles<'m> {
    pub project: &'m FnDef,
    pub evaluate: &'m FnDef,
    pub tile_cull: Option<&'m FnDef>,
    pub pixel_info: Option<&'m FnDef>,
    /// `project`'s first parameter.
    pub params: Ty,
    /// `Projected<Cull, Shade>`'s arguments.
    pub cull: Ty,
    pub shade: Ty,
    /// `evaluate`'s first parameter (`pixel_info`'s result, or the pixel centre).
    pub pixel: Ty,
    /// `Contribution<Color>`'s argument.
    pub color: Ty,
}

impl Roles<'_> {
    /// Whether `f` is one of the role functions.
    pub fn has(&self, f: &FnDef) -> bool {
        [
            Some(self.project),
            self.tile_cull,
            self.pixel_info,
            Some(self.evaluate),
        ]
        .into_iter()
        .flatten()
        .any(|r| std::ptr::eq(r, f))
    }
}

impl Checked<'_> {
    /// Whether `f` is the user-written adjoint of a helper (not a kernel of its own).
    pub fn is_adjoint(&self, f: &FnDef) -> bool {
        self.adjoints.iter().any(|(_, a)| std::ptr::eq(*a, f))
    }
}

/// Checks `m`'s signatures; every error found is reported. A module with items that failed
/// to parse is not checked: its errors would be about the functions the parse dropped.
pub fn check<'m>(kind: Kind, m: &'m Module, diag: &Diag) -> Option<Checked<'m>> {
    if diag.has_errors() {
        return None;
    }
    let adjoints = adjoints(m, diag);
    let roles = match kind {
        Kind::Method => Some(roles(m, diag)?),
        Kind::Functions => None,
    };
    let adjoints = adjoints?;
    Some(Checked {
        module: m,
        adjoints,
        roles,
    })
}

/// Each helper with `#[adjoint(f)]` and `f`, which takes the helper's parameters, then the
/// cotangent of its result, and returns the cotangents of the parameters.
fn adjoints<'m>(m: &'m Module, diag: &Diag) -> Option<Vec<(&'m FnDef, &'m FnDef)>> {
    let mut out = vec![];
    let mut ok = true;
    for h in m.fns.iter().filter(|f| f.adjoint.is_some()) {
        let adj_ident = h.adjoint.as_ref().expect("filtered");
        let Some(adj) = m.find_fn(&adj_ident.to_string()) else {
            diag.error_at(
                adj_ident,
                format!("cannot find the adjoint function `{adj_ident}` in this module"),
            );
            ok = false;
            continue;
        };
        let params: Vec<Ty> = h.params.iter().map(|p| p.ty.clone()).collect();
        let want: Vec<Ty> = params.iter().chain([&h.ret]).cloned().collect();
        let got: Vec<Ty> = adj.params.iter().map(|p| p.ty.clone()).collect();
        let want_ret = match <[Ty; 1]>::try_from(params.clone()) {
            Ok([one]) => one,
            Err(_) => Ty::Tuple(params),
        };
        if got != want || adj.ret != want_ret {
            let shown: Vec<String> = want.iter().map(|t| t.to_string()).collect();
            diag.error_at(
                &adj.item.sig.ident,
                format!(
                    "the adjoint of `{}` must have the signature fn({}) -> {}: the helper's parameters, then the cotangent of its result; it returns the cotangents of the parameters",
                    h.name,
                    shown.join(", "),
                    want_ret
                ),
            );
            ok = false;
            continue;
        }
        out.push((h, adj));
    }
    ok.then_some(out)
}

const LIBRARY_STRUCT: &str = "a building block's struct, which lives only inside kernels: \
     give the method a struct of its own with the fields it keeps";

/// A method's roles against `splat_runtime::SplatMethod`'s contract.
fn roles<'m>(m: &'m Module, diag: &Diag) -> Option<Roles<'m>> {
    let missing = |what: &str, returns: &str| {
        let need = format!(
            "a #[splat_method] module needs `fn {what}` (see splat_runtime::SplatMethod for the signature)"
        );
        match near_miss(m, what, returns) {
            Some((f, hint)) => diag.error_at(&f.item.sig.ident, format!("{need}; {hint}")),
            None => diag.error_at(&m.name, need),
        }
    };
    let role = |name: &str| m.fns.iter().find(|f| !f.builtin && f.name == name);
    let (project, evaluate) = (role("project"), role("evaluate"));
    if project.is_none() {
        missing("project", "Projected");
    }
    if evaluate.is_none() {
        missing("evaluate", "Contribution");
    }
    let (project, evaluate) = (project?, evaluate?);
    let (tile_cull, pixel_info) = (role("tile_cull"), role("pixel_info"));
    let camera = plain_builtin("Camera");
    check_params(
        project,
        &[("the parameters", None), ("the camera", Some(&camera))],
        diag,
    )?;
    let (Some(cull), Some(shade)) = (
        struct_field(&project.ret, "cull"),
        struct_field(&project.ret, "shade"),
    ) else {
        diag.error_at(
            &project.item.sig.output,
            "`project` must return `Projected<Cull, Shade>`",
        );
        return None;
    };
    for (what, t) in [("cull", &cull), ("shade", &shade)] {
        if let Some(block) = crate::blocks::struct_in(t) {
            diag.error_at(
                &project.item.sig.output,
                format!("the {what} data of `project` holds `{block}`, {LIBRARY_STRUCT}"),
            );
            return None;
        }
    }
    check_params(
        evaluate,
        &[("the pixel data", None), ("the shade data", Some(&shade))],
        diag,
    )?;
    let pixel = evaluate.params[0].ty.clone();
    let Some(color) = struct_field(&evaluate.ret, "color") else {
        diag.error_at(
            &evaluate.item.sig.output,
            "`evaluate` must return `Contribution<Color>`",
        );
        return None;
    };
    let lanes = "(they become SIMD lanes)";
    if !pixel.all_float() {
        diag.error_at(
            &written_type(evaluate, 0),
            format!("the pixel data of `evaluate` must be made of f32 only {lanes}"),
        );
        return None;
    }
    if !color.all_float() {
        diag.error_at(
            &evaluate.item.sig.output,
            format!("the color of `evaluate` must be made of f32 only {lanes}"),
        );
        return None;
    }
    if let Some(tc) = tile_cull {
        let tile = plain_builtin("Tile");
        check_params(
            tc,
            &[("the tile", Some(&tile)), ("the cull data", Some(&cull))],
            diag,
        )?;
        if tc.ret != Ty::Bool {
            diag.error_at(&tc.item.sig.output, "`tile_cull` must return `bool`");
            return None;
        }
    }
    match pixel_info {
        Some(pi) => {
            check_params(
                pi,
                &[
                    ("the pixel centre", Some(&Ty::Vec(2))),
                    ("the camera", Some(&camera)),
                ],
                diag,
            )?;
            if pi.ret != pixel {
                diag.error_at(
                    &pi.item.sig.output,
                    format!("`pixel_info` must return `{pixel}`"),
                );
                return None;
            }
        }
        None if pixel != Ty::Vec(2) => {
            diag.error_at(
                &written_type(evaluate, 0),
                "without `pixel_info`, the pixel data of `evaluate` is the pixel centre: `Vec2`",
            );
            return None;
        }
        None => {}
    }
    Some(Roles {
        params: project.params[0].ty.clone(),
        project,
        evaluate,
        tile_cull,
        pixel_info,
        cull,
        shade,
        pixel,
        color,
    })
}

fn struct_field(ty: &Ty, name: &str) -> Option<Ty> {
    match ty {
        Ty::Struct(s) => s
            .fields
            .iter()
            .find(|(f, _)| f == name)
            .map(|(_, t)| t.clone()),
        _ => None,
    }
}

/// The type of parameter `i` of `def` as written, for errors about it (the parameter itself
/// when the type cannot be found).
fn written_type(def: &FnDef, i: usize) -> &dyn quote::ToTokens {
    match def.item.sig.inputs.iter().nth(i) {
        Some(syn::FnArg::Typed(t)) => &*t.ty,
        Some(other) => other,
        None => &def.item.sig.ident,
    }
}

/// Checks that `def` has the parameter types `want` (by position); `None` after reporting
/// otherwise.
fn check_params(def: &FnDef, want: &[(&str, Option<&Ty>)], diag: &Diag) -> Option<()> {
    if def.params.len() != want.len() {
        let names: Vec<&str> = want.iter().map(|w| w.0).collect();
        diag.error(
            def.item.sig.paren_token.span.join(),
            format!(
                "`{}` must take {} parameter(s): {}",
                def.name,
                want.len(),
                names.join(", ")
            ),
        );
        return None;
    }
    for (i, (p, (what, ty))) in def.params.iter().zip(want).enumerate() {
        if let Some(block) = crate::blocks::struct_in(&p.ty) {
            diag.error_at(
                &written_type(def, i),
                format!("{what} of `{}` holds `{block}`, {LIBRARY_STRUCT}", def.name),
            );
            return None;
        }
        if let Some(t) = ty
            && p.ty != **t
        {
            diag.error_at(
                &written_type(def, i),
                format!("{what} of `{}` must be `{t}`, found `{}`", def.name, p.ty),
            );
            return None;
        }
    }
    Some(())
}

/// The user function that was probably meant as the missing role function `role`: one that
/// returns the role's type (`returns`) under another name, or a name one or two edits away.
fn near_miss<'m>(m: &'m Module, role: &str, returns: &str) -> Option<(&'m FnDef, String)> {
    let user = || m.fns.iter().filter(|f| !f.builtin);
    let typed = user().find(|f| matches!(&f.ret, Ty::Struct(s) if s.display.starts_with(returns)));
    if let Some(f) = typed {
        let hint = format!("`fn {}` returns `{returns}`: name it `{role}`", f.name);
        return Some((f, hint));
    }
    let (distance, f) = user()
        .map(|f| (edit_distance(&f.name, role), f))
        .min_by_key(|(d, _)| *d)?;
    (distance <= 2).then(|| (f, format!("did you mean `{role}` for `fn {}`?", f.name)))
}

#[cfg(test)]
mod tests {
    use crate::{Kind, compile_ir};

    /// A method with `items` after a `project` whose shade data is one `f32`.
    fn method(items: &str) -> String {
        format!(
            "mod m {{
                pub struct P {{ pub x: Vec3 }}
                pub fn project(p: &P, cam: &Camera) -> Projected<f32, f32> {{
                    Projected {{ visible: true, depth: 1.0, bbox_min: Vec2::ZERO,
                        bbox_max: Vec2::ONE, cull: 0.0, shade: p.x.x }}
                }}
                {items}
            }}"
        )
    }

    const EVALUATE: &str = "pub fn evaluate(px: Vec2, s: &f32) -> Contribution<Vec3> {
        Contribution { alpha: *s + px.x, color: Vec3::ONE, valid: true }
    }";

    fn errors(kind: Kind, src: &str) -> Vec<String> {
        let item: syn::ItemMod = syn::parse_str(src).expect("valid Rust");
        match compile_ir(kind, item) {
            Ok(_) => vec![],
            Err(e) => e,
        }
    }

    /// The one error `src` has, which must contain `want`.
    fn fails_with(kind: Kind, src: &str, want: &str) {
        let e = errors(kind, src);
        assert!(
            e.len() == 1 && e[0].contains(want),
            "expected one error with {want:?}, got {e:?}"
        );
    }

    #[test]
    fn the_base_method_compiles() {
        assert_eq!(
            errors(Kind::Method, &method(EVALUATE)),
            Vec::<String>::new()
        );
    }

    #[test]
    fn a_signature_that_fails_to_parse_is_its_only_error() {
        let bad = EVALUATE.replace("s: &f32", "s: &f64");
        fails_with(Kind::Method, &method(&bad), "f64");
        // A call to a helper the parse dropped is not reported again.
        let src = "mod m {
            fn h(x: &mut f32) -> f32 { 1.0 }
            fn f(x: f32) -> f32 { h(x) }
        }";
        fails_with(Kind::Functions, src, "&mut");
    }

    #[test]
    fn an_adjoint_that_is_missing_or_mistyped_is_refused() {
        let helper = |adjoint: &str| {
            format!(
                "mod m {{
                    #[adjoint(h_adjoint)]
                    fn h(x: f32, y: Vec2) -> f32 {{ x * y.x }}
                    {adjoint}
                    fn f(x: f32) -> f32 {{ h(x, Vec2::ONE) }}
                }}"
            )
        };
        fails_with(
            Kind::Functions,
            &helper(""),
            "cannot find the adjoint function `h_adjoint`",
        );
        fails_with(
            Kind::Functions,
            &helper("fn h_adjoint(x: f32, y: Vec2, d: f32) -> f32 { d }"),
            "must have the signature fn(f32, Vec2, f32) -> (f32, Vec2)",
        );
        let right =
            "fn h_adjoint(x: f32, y: Vec2, d: f32) -> (f32, Vec2) { (d * y.x, Vec2::ZERO) }";
        assert_eq!(
            errors(Kind::Functions, &helper(right)),
            Vec::<String>::new()
        );
    }

    #[test]
    fn role_functions_are_held_to_the_runtime_contract() {
        let vec3_pixel = EVALUATE.replace("px: Vec2", "px: Vec3");
        let cases = [
            (
                [
                    EVALUATE,
                    "pub fn tile_cull(t: &Tile, c: &f32) -> f32 { 1.0 }",
                ]
                .concat(),
                "`tile_cull` must return `bool`",
            ),
            (
                [
                    EVALUATE,
                    "pub fn tile_cull(t: &Tile, c: &Vec2) -> bool { true }",
                ]
                .concat(),
                "the cull data of `tile_cull` must be `f32`",
            ),
            (
                [
                    &vec3_pixel,
                    "pub fn pixel_info(px: Vec2, cam: &Camera) -> Vec2 { px }",
                ]
                .concat(),
                "`pixel_info` must return `Vec3`",
            ),
            (
                vec3_pixel.clone(),
                "without `pixel_info`, the pixel data of `evaluate` is the pixel centre",
            ),
            (
                EVALUATE.replace("px: Vec2", "px: u32"),
                "must be made of f32 only",
            ),
            (
                (EVALUATE.replace("Contribution<Vec3>", "Contribution<u32>"))
                    .replace("Vec3::ONE", "1"),
                "the color of `evaluate`",
            ),
        ];
        for (items, want) in cases {
            fails_with(Kind::Method, &method(&items), want);
        }
    }
}
