//! The effects a frame simulates, as the scene and the request switch them on, and how each
//! is carried: by a kernel variant compiled for it, by a method instance, or by a buffer that
//! exists only when asked for. What `splat render --explain` and `splat fit --explain` print.

use crate::frame::RenderOptions;
use crate::method::SplatMethod;
use crate::types::{Camera, CameraModel};
use std::fmt;

/// The effects of rendering with one method, camera and set of options.
#[derive(Clone, Debug, PartialEq)]
pub struct Effects {
    pub method: &'static str,
    pub camera_model: CameraModel,
    /// The fisheye's distortion coefficients are not all zero.
    pub distortion: bool,
    /// The kernels compiled for `camera_model` alone that the frame runs (`project_pinhole`,
    /// ...): empty when the method reads no camera model (it is pinhole-only).
    pub model_variants: Vec<&'static str>,
    /// The camera moves during its readout (the method is one that renders it: the runtime
    /// refuses the others).
    pub rolling_shutter: bool,
    /// Color (or feature) channels.
    pub channels: usize,
    /// The outputs asked for (alpha, depth: without it no depth is summed and no buffer holds
    /// it) and the renderer's settings.
    pub options: RenderOptions,
    /// For frames with a backward pass ([`Effects::with_gradients`]): which gradients it
    /// computes.
    pub gradients: Option<GradientEffects>,
}

/// The gradients a backward pass computes: `options.gradients` by name.
#[derive(Clone, Debug, PartialEq)]
pub struct GradientEffects {
    /// Parameter groups whose gradients are computed.
    pub computed: Vec<&'static str>,
    /// Groups left out: the gated adjoints never compute their cotangents.
    pub skipped: Vec<&'static str>,
    /// The camera's gradient (with it, its share through each pixel's ray).
    pub camera: bool,
    /// Whether a gradient asked for flows through `evaluate`'s alpha
    /// ([`GradientSet::alpha_cotangent`](crate::GradientSet::alpha_cotangent)): without it the
    /// blend sums nothing of what lies behind each entry.
    pub alpha_cotangent: bool,
}

impl Effects {
    pub fn of<M: SplatMethod>(camera: &Camera, options: &RenderOptions) -> Effects {
        let suffix = format!("_{}", camera.model);
        Effects {
            method: M::NAME,
            camera_model: camera.model,
            distortion: camera.model == CameraModel::KannalaBrandt
                && camera.distortion.abs().max_element() > 0.0,
            model_variants: M::SOURCE
                .functions
                .iter()
                .map(|f| f.kernel)
                .filter(|k| k.ends_with(&suffix))
                .collect(),
            rolling_shutter: camera.has_rolling_shutter(),
            channels: <M::Color as crate::Flat>::LEN,
            options: *options,
            gradients: None,
        }
    }

    /// The effects of a frame with a backward pass, which computes `options.gradients`.
    pub fn with_gradients<M: SplatMethod>(self) -> Effects {
        let set = self.options.gradients;
        let groups = |computed: bool| {
            let fields = M::PARAM_FIELDS.iter().enumerate();
            let picked = fields.filter(|(k, _)| set.param(*k) == computed);
            picked.map(|(_, (name, _))| *name).collect()
        };
        Effects {
            gradients: Some(GradientEffects {
                computed: groups(true),
                skipped: groups(false),
                camera: set.camera(),
                alpha_cotangent: set.alpha_cotangent::<M>(),
            }),
            ..self
        }
    }
}

impl fmt::Display for Effects {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let on = |b: bool| if b { "on" } else { "off" };
        writeln!(f, "method            {}", self.method)?;
        let camera = match self.model_variants.is_empty() {
            true => "the method reads no camera model: pinhole only".to_string(),
            false => format!(
                "kernels compiled for it alone: {}",
                self.model_variants.join(", ")
            ),
        };
        writeln!(f, "camera model      {} ({camera})", self.camera_model)?;
        if self.camera_model == CameraModel::KannalaBrandt {
            writeln!(
                f,
                "distortion        {} (the fisheye polynomial is evaluated either way)",
                on(self.distortion)
            )?;
        }
        let shutter = match self.rolling_shutter {
            true => "on (each row seen from the camera's pose at its readout)",
            false => "off (a global shutter)",
        };
        writeln!(f, "rolling shutter   {shutter}")?;
        writeln!(f, "color channels    {}", self.channels)?;
        let o = &self.options;
        writeln!(f, "alpha output      {}", on(o.alpha))?;
        let depth = match o.depth {
            true => "on",
            false => "off (no depth sums, no depth buffer)",
        };
        writeln!(f, "depth output      {depth}")?;
        writeln!(f, "state precision   {}", o.precision.name())?;
        writeln!(f, "shade precision   {}", o.shade_precision.name())?;
        if self.gradients.is_some() {
            writeln!(f, "gradient sums     {}", o.gradient_precision.name())?;
        }
        let p_max = o.p_max.map_or("off".to_string(), |p| p.to_string());
        writeln!(f, "P_max             {p_max}")?;
        write!(
            f,
            "tile              {} px, tile cull {}",
            o.tile_size,
            on(o.tile_cull)
        )?;
        if let Some(g) = &self.gradients {
            let skipped = match g.skipped.is_empty() {
                true => String::new(),
                false => format!(" (never computed: {})", g.skipped.join(", ")),
            };
            let camera = match g.camera {
                true => "on",
                false => "off (no ray adjoint per pixel)",
            };
            let alpha = match g.alpha_cotangent {
                true => "on",
                false => "off (no gradient asked for flows through alpha)",
            };
            write!(
                f,
                "\ngradients         {}{skipped}\ncamera gradient   {camera}\nalpha cotangent   {alpha}",
                g.computed.join(", ")
            )?;
        }
        Ok(())
    }
}
