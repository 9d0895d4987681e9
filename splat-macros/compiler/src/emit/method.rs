//! The `SplatMethod` implementation of a `#[splat_method]` module: the glue between the
//! user's four functions and the runtime's contract.

use super::api::{Kernel, pack, slot_access};
use crate::check::Roles;
use crate::ir::Scalar;
use crate::model::FnDef;
use crate::types::{Ty, plain_builtin};
use proc_macro2::{Literal, TokenStream};
use quote::quote;

/// The `method::Twin` of the method: its f64 twins (module `twin`) behind slice signatures.
fn twin_const(has_pixel_info: bool) -> TokenStream {
    let rt = quote!(::splat_runtime);
    let f = |name: &str| {
        let id = syn::Ident::new(name, proc_macro2::Span::call_site());
        quote! {
            |x: &[f64], i: &[u32]| {
                let (a, b) = twin::#id(
                    x.try_into().expect("the twin's float inputs"),
                    i.try_into().expect("the twin's integer inputs"),
                );
                (a.to_vec(), b.to_vec())
            }
        }
    };
    let adjoint = |name: &str| {
        let id = syn::Ident::new(name, proc_macro2::Span::call_site());
        quote! {
            |x: &[f64], i: &[u32], d: &[f64]| {
                twin::#id(
                    x.try_into().expect("the twin's float inputs"),
                    i.try_into().expect("the twin's integer inputs"),
                    d.try_into().expect("the twin's output cotangents"),
                )
                .to_vec()
            }
        }
    };
    let (pixel_info, pixel_info_adjoint) = match has_pixel_info {
        true => {
            let (p, a) = (f("pixel_info"), adjoint("pixel_info_adjoint"));
            (quote!(Some(#p)), quote!(Some(#a)))
        }
        false => (quote!(None), quote!(None)),
    };
    let (project, project_adjoint) = (f("project"), adjoint("project_adjoint"));
    let (evaluate, evaluate_adjoint) = (f("evaluate"), adjoint("evaluate_adjoint"));
    quote! {
        #rt::method::Twin {
            project: #project,
            project_adjoint: #project_adjoint,
            pixel_info: #pixel_info,
            pixel_info_adjoint: #pixel_info_adjoint,
            evaluate: #evaluate,
            evaluate_adjoint: #evaluate_adjoint,
        }
    }
}

/// Arguments for calling the user's function from the trait method, whose parameters are
/// all references except `pixel_info`'s pixel (`by_value` names those passed by value).
fn call_args(def: &FnDef, names: &[TokenStream], by_value: &[bool]) -> Vec<TokenStream> {
    def.params
        .iter()
        .zip(names)
        .zip(by_value)
        .map(|((p, n), owned)| match (p.by_ref, owned) {
            (true, false) | (false, true) => quote!(#n),
            (false, false) => quote!(*#n),
            (true, true) => quote!(&#n),
        })
        .collect()
}

/// The `Method` struct and its `SplatMethod` impl; `name` is what users see
/// (`SplatMethod::NAME`).
pub fn method_impl(name: &str, roles: &Roles, kernels: &[Kernel]) -> TokenStream {
    let kernel = |def: &FnDef| {
        let k = kernels.iter().find(|k| std::ptr::eq(k.def, def));
        k.expect("every role function of a checked method is a kernel")
    };
    let (project, evaluate) = (kernel(roles.project), kernel(roles.evaluate));
    let tile_cull = roles.tile_cull.map(kernel);
    let pixel_info = roles.pixel_info.map(kernel);
    let camera = plain_builtin("Camera");
    let Roles {
        params: params_ty,
        cull: cull_ty,
        shade: shade_ty,
        pixel: pixel_ty,
        color: color_ty,
        ..
    } = roles;

    let param_fields: Vec<TokenStream> = match &params_ty {
        Ty::Struct(s) => s
            .fields
            .iter()
            .map(|(name, t)| {
                let n = t.slot_count();
                quote!((#name, #n))
            })
            .collect(),
        t => {
            let n = t.slot_count();
            vec![quote!(("params", #n))]
        }
    };
    let shade_field_groups =
        crate::gate::shade_field_groups(&project.primal, params_ty, &camera, shade_ty);
    let alpha_groups = crate::gate::alpha_groups(&evaluate.primal, pixel_ty, shade_ty);
    let (p_t, c_t, s_t, px_t, col_t) = (
        params_ty.rust(),
        cull_ty.rust(),
        shade_ty.rust(),
        pixel_ty.rust(),
        color_ty.rust(),
    );
    let (np, nc) = (pixel_ty.slot_count(), color_ty.slot_count());
    let f32x8 = quote!(::splat_runtime::F32x8);
    let u32x8 = quote!(::splat_runtime::U32x8);
    let rt = quote!(::splat_runtime);

    let project_call = call_args(
        project.def,
        &[quote!(params), quote!(camera)],
        &[false, false],
    );
    // Every parameter group asked for: the plain adjoint (the AD's own statement order, so
    // that costs what it did before gating), the camera dropped unless asked for; otherwise
    // the gated one. `by_model` turns each call into its model's.
    let all_params = crate::gate::all_fields(params_ty);
    let choose_project_adjoint = |model: &dyn Fn(TokenStream) -> TokenStream| {
        let plain = model(quote!(project_adjoint(#(#project_call,)* *d_out)));
        let gated = model(quote!(project_adjoint_gated(#(#project_call,)* *d_out, wanted.bits())));
        quote! {
            if wanted.bits() & #all_params == #all_params {
                let (p, c) = #plain;
                (p, if wanted.camera() { c } else { #rt::Camera::ZERO })
            } else {
                #gated
            }
        }
    };
    let project_adjoint = match project.adjoint {
        Some(_) => choose_project_adjoint(&|call| call),
        None => quote! { (<#p_t as #rt::Flat>::zero(), #rt::Camera::ZERO) },
    };
    let tile_cull_body = match tile_cull {
        Some(tc) => {
            let a = call_args(tc.def, &[quote!(tile), quote!(cull)], &[false, false]);
            quote!(tile_cull(#(#a),*))
        }
        None => quote!(true),
    };
    let pixel_info_body = match pixel_info {
        Some(pi) => {
            let a = call_args(pi.def, &[quote!(pixel), quote!(camera)], &[true, false]);
            quote!(pixel_info(#(#a),*))
        }
        None => quote!(pixel),
    };
    // The camera's cotangent through the pixel data (rays depend on the camera).
    let pixel_info_adjoint_body = match pixel_info {
        Some(pi) if pi.adjoint.is_some() => {
            let a = call_args(pi.def, &[quote!(pixel), quote!(camera)], &[true, false]);
            quote!(pixel_info_adjoint(#(#a,)* *d_out).1)
        }
        _ => quote!(#rt::Camera::ZERO),
    };
    // The same calls through the kernels specialized to the camera model `MODEL`.
    let project_as = by_model(project, quote!(project(#(#project_call),*)));
    let project_adjoint_as = match project.adjoint {
        Some(_) => choose_project_adjoint(&|call| by_model(project, call)),
        None => project_adjoint.clone(),
    };
    let (pixel_info_as, pixel_info_adjoint_as) = match pixel_info {
        Some(pi) => (
            by_model(pi, pixel_info_body.clone()),
            match pi.adjoint {
                Some(_) => by_model(pi, pixel_info_adjoint_body.clone()),
                None => pixel_info_adjoint_body.clone(),
            },
        ),
        None => (pixel_info_body.clone(), pixel_info_adjoint_body.clone()),
    };
    let eval_call = call_args(
        evaluate.def,
        &[quote!(pixel), quote!(shade)],
        &[false, false],
    );

    // Lane wrappers: pixel slots come from the lanes, shade slots are broadcast.
    let shade_slots = shade_ty.slots();
    let shade_access = slot_access(shade_ty, quote!(shade));
    let idx = Literal::usize_unsuffixed;
    let mut lane_in: Vec<TokenStream> = (0..np)
        .map(|i| {
            let i = idx(i);
            quote!(pixel[#i])
        })
        .collect();
    let mut lane_int = vec![];
    for (s, a) in shade_slots.iter().zip(&shade_access) {
        match s {
            Scalar::F32 => lane_in.push(quote!(#f32x8::splat(#a))),
            _ => lane_int.push(quote!(#u32x8::splat(#a as u32))),
        }
    }
    let color_lanes: Vec<TokenStream> = (1..=nc)
        .map(|i| {
            let i = idx(i);
            quote!(__out[#i])
        })
        .collect();
    let d_color: Vec<TokenStream> = (0..nc)
        .map(|i| {
            let i = idx(i);
            quote!(d_out.color[#i])
        })
        .collect();
    let mut bar_index = np;
    let mut shade_bars = shade_slots
        .iter()
        .map(|s| match s {
            Scalar::F32 => {
                bar_index += 1;
                let k = idx(bar_index - 1);
                quote!(__bars[#k].masked_sum(active))
            }
            Scalar::Bool => quote!(false),
            Scalar::U32 => quote!(0u32),
            Scalar::I32 => quote!(0i32),
        })
        .collect::<Vec<_>>()
        .into_iter();
    let shade_from_bars = pack(shade_ty, &mut shade_bars);
    // The same packing from plain float sums, and the lane-wise accumulation.
    let mut from_sums = float_slots(&shade_slots);
    let float_index = shade_slots.iter().filter(|s| **s == Scalar::F32).count();
    let shade_from_sums = pack(shade_ty, &mut from_sums);
    let params_from_sums = pack(params_ty, &mut float_slots(&params_ty.slots()));
    let nsf = idx(float_index);
    let mut accumulate: Vec<TokenStream> = (0..float_index)
        .map(|k| {
            let (a, b) = (idx(k), idx(np + k));
            quote!(acc[#a] = acc[#a] + active.select_f32(__bars[#b], #f32x8::splat(0.0));)
        })
        .collect();
    // Only a method with `pixel_info` has pixel data that depends on anything.
    if pixel_info.is_some() {
        accumulate.extend((0..np).map(|k| {
            let k = idx(k);
            quote!(d_pixel[#k] = d_pixel[#k] + active.select_f32(__bars[#k], #f32x8::splat(0.0));)
        }));
    }
    let eval_adjoint = if evaluate.adjoint.is_some() {
        quote! { evaluate_adjoint(#(#eval_call,)* *d_out).1 }
    } else {
        quote! { <#s_t as #rt::Flat>::zero() }
    };
    // The blend calls the gated lane adjoint alone, whatever is asked for: with every group
    // asked for it runs as fast as the plain one (within 1%, backward pass of 3DGS, 3DGUT and
    // 3DGEER), and inlining both into every blend instance made a training test's build 2.7x
    // longer.
    let lanes_accumulate = if evaluate.adjoint.is_some() {
        quote! {
            let __in = [#(#lane_in),*];
            let __int = [#(#lane_int),*];
            let __d = [d_out.alpha, #(#d_color),*];
            let __bars = lanes::evaluate_adjoint_gated(&__in, &__int, &__d, shade_groups);
            #(#accumulate)*
        }
    } else {
        quote! {}
    };
    let lanes_adjoint = if evaluate.adjoint.is_some() {
        quote! {
            let __d = [d_out.alpha, #(#d_color),*];
            let __bars = lanes::evaluate_adjoint(&__in, &__int, &__d);
            #shade_from_bars
        }
    } else {
        quote! { <#s_t as #rt::Flat>::zero() }
    };
    let (has_tc, has_pi) = (tile_cull.is_some(), pixel_info.is_some());
    let pixels_by_model = pixel_info.is_some_and(|pi| !pi.models.is_empty());
    let generic_camera = kernels.iter().any(|k| k.camera_model);
    let rolling_shutter = kernels.iter().any(|k| k.rolling_shutter);
    let twin = twin_const(has_pi);
    let (np, nc) = (idx(np), idx(nc));
    quote! {
        /// The method as the runtime sees it.
        #[derive(Clone, Copy, Debug, Default)]
        pub struct Method;

        #[allow(unused_variables, clippy::all)]
        impl #rt::SplatMethod for Method {
            const NAME: &'static str = #name;
            const HAS_TILE_CULL: bool = #has_tc;
            const HAS_PIXEL_INFO: bool = #has_pi;
            const PIXELS_BY_MODEL: bool = #pixels_by_model;
            const GENERIC_CAMERA: bool = #generic_camera;
            const ROLLING_SHUTTER: bool = #rolling_shutter;
            const PARAM_FIELDS: &'static [(&'static str, usize)] = &[#(#param_fields),*];
            const SHADE_FIELD_GROUPS: &'static [u32] = &[#(#shade_field_groups),*];
            const ALPHA_GROUPS: u32 = #alpha_groups;
            const SOURCE: #rt::GeneratedSource = #rt::GeneratedSource { rust: GENERATED_RUST, wgsl: GENERATED_WGSL, functions: GENERATED_FUNCTIONS };
            const TWIN: #rt::method::Twin = #twin;
            type Params = #p_t;
            type Cull = #c_t;
            type Shade = #s_t;
            type Pixel = #px_t;
            type Color = #col_t;
            type PixelLanes = [#f32x8; #np];
            type ColorLanes = [#f32x8; #nc];
            type ShadeLanes = [#f32x8; #nsf];

            #[inline]
            fn project(params: &#p_t, camera: &#rt::Camera) -> #rt::Projected<#c_t, #s_t> {
                project(#(#project_call),*)
            }
            #[inline]
            fn project_adjoint(params: &#p_t, camera: &#rt::Camera, d_out: &#rt::Projected<#c_t, #s_t>, wanted: #rt::GradientSet) -> (#p_t, #rt::Camera) {
                #project_adjoint
            }
            #[inline]
            fn project_as<const MODEL: u32>(params: &#p_t, camera: &#rt::Camera) -> #rt::Projected<#c_t, #s_t> {
                #project_as
            }
            #[inline]
            fn project_adjoint_as<const MODEL: u32>(params: &#p_t, camera: &#rt::Camera, d_out: &#rt::Projected<#c_t, #s_t>, wanted: #rt::GradientSet) -> (#p_t, #rt::Camera) {
                #project_adjoint_as
            }
            #[inline]
            fn pixel_info_as<const MODEL: u32>(pixel: #rt::glam::Vec2, camera: &#rt::Camera) -> #px_t {
                #pixel_info_as
            }
            #[inline]
            fn pixel_info_adjoint_as<const MODEL: u32>(pixel: #rt::glam::Vec2, camera: &#rt::Camera, d_out: &#px_t) -> #rt::Camera {
                #pixel_info_adjoint_as
            }
            #[inline]
            fn tile_cull(tile: &#rt::Tile, cull: &#c_t) -> bool {
                #tile_cull_body
            }
            #[inline]
            fn pixel_info(pixel: #rt::glam::Vec2, camera: &#rt::Camera) -> #px_t {
                #pixel_info_body
            }
            #[inline]
            fn evaluate(pixel: &#px_t, shade: &#s_t) -> #rt::Contribution<#col_t> {
                evaluate(#(#eval_call),*)
            }
            #[inline]
            fn evaluate_adjoint(pixel: &#px_t, shade: &#s_t, d_out: &#rt::Contribution<#col_t>) -> #s_t {
                #eval_adjoint
            }
            #[inline(always)]
            fn evaluate_lanes(pixel: &[#f32x8; #np], shade: &#s_t) -> #rt::ContributionLanes<[#f32x8; #nc]> {
                let __in = [#(#lane_in),*];
                let __int = [#(#lane_int),*];
                let (__out, __outi) = lanes::evaluate(&__in, &__int);
                #rt::ContributionLanes { alpha: __out[0], color: [#(#color_lanes),*], valid: __outi[0].to_mask() }
            }
            #[inline(always)]
            fn evaluate_adjoint_lanes(
                pixel: &[#f32x8; #np],
                shade: &#s_t,
                d_out: &#rt::ContributionLanes<[#f32x8; #nc]>,
                active: #rt::M32x8,
            ) -> #s_t {
                let __in = [#(#lane_in),*];
                let __int = [#(#lane_int),*];
                #lanes_adjoint
            }
            #[inline(always)]
            fn evaluate_adjoint_lanes_accumulate(
                pixel: &[#f32x8; #np],
                shade: &#s_t,
                d_out: &#rt::ContributionLanes<[#f32x8; #nc]>,
                active: #rt::M32x8,
                acc: &mut [#f32x8; #nsf],
                d_pixel: &mut [#f32x8; #np],
                shade_groups: u32,
            ) {
                #lanes_accumulate
            }
            #[inline]
            fn pixel_info_adjoint(pixel: #rt::glam::Vec2, camera: &#rt::Camera, d_out: &#px_t) -> #rt::Camera {
                #pixel_info_adjoint_body
            }
            #[inline]
            fn shade_from_float_slots(sums: &[f32]) -> #s_t {
                #shade_from_sums
            }
            #[inline]
            fn params_from_float_slots(sums: &[f32]) -> #p_t {
                #params_from_sums
            }
        }
    }
}

/// `call`, a call of a kernel's module-level function (`project(params, camera)`), made
/// through the kernel's variant for the camera model `MODEL` where it has variants (a const
/// generic: each instantiation keeps one arm).
fn by_model(k: &Kernel, call: TokenStream) -> TokenStream {
    if k.models.is_empty() {
        return call;
    }
    let arms = k.models.iter().map(|(model, code, _)| {
        let module = quote::format_ident!("{model}");
        quote!(#code => #module::#call)
    });
    quote! {
        match MODEL {
            #(#arms,)*
            _ => unreachable!("camera model codes are those of CameraModel"),
        }
    }
}

/// `sums[k]` for the k-th float slot of `slots`, zero for the others (cotangents of bools and
/// integers).
fn float_slots(slots: &[Scalar]) -> std::vec::IntoIter<TokenStream> {
    let mut k = 0usize;
    slots
        .iter()
        .map(|s| match s {
            Scalar::F32 => {
                let i = proc_macro2::Literal::usize_unsuffixed(k);
                k += 1;
                quote!(sums[#i])
            }
            Scalar::Bool => quote!(false),
            Scalar::U32 => quote!(0u32),
            Scalar::I32 => quote!(0i32),
        })
        .collect::<Vec<_>>()
        .into_iter()
}
