//! The methods a `splat` command line offers. Each is a name, a line of help and its compiled
//! instances (one, or one per SH degree); what each command runs for an instance is built from
//! its types here, once, so the commands themselves never name a method.

use crate::bench::Bench;
use crate::fit::Fit;
use crate::render::{Frames, Render};
use crate::tradeoff::{Outcome, PaceFrame, Tradeoff};
use anyhow::{Result, bail};
use splat_runtime::io::ply::{FromStored, GaussianCloud, ToStored};
use splat_runtime::train::Trainable;
use splat_runtime::{Camera, CameraModel, Effects, GeneratedSource, RenderOptions, SplatMethod};

/// A method on the command line.
pub struct Method {
    pub name: &'static str,
    pub help: &'static str,
    /// `instances[k]` renders scenes of SH degree k; the last one higher degrees, training and
    /// `inspect`.
    instances: Vec<Instance>,
    /// What renders a camera with a rolling shutter, if the method can.
    rolling_shutter: Option<Instance>,
    /// Whether it evaluates its primitives exactly: `splat tradeoff` compares every method's
    /// render of the same Gaussians with this one's.
    pub(crate) exact: bool,
    /// What its primitives are where they are not Gaussians (LinPrim's octahedra): its scene
    /// is stored as the Gaussians closest to them, which `splat fit --export` refuses to ship
    /// to viewers that would draw them as Gaussians.
    pub(crate) not_gaussians: Option<&'static str>,
    /// Whether it renders antialiased (3DGS-AA): the scenes it trains say so where a format
    /// keeps the flag, and a scene that says so is noted when another method renders it.
    pub(crate) antialiased: bool,
}

/// One compiled method: what each command does with it.
#[derive(Clone, Copy)]
pub struct Instance {
    pub(crate) source: GeneratedSource,
    /// Whether it renders every camera model (else pinhole only).
    pub(crate) generic_camera: bool,
    /// Whether it renders a rolling shutter (else global shutters only).
    pub(crate) rolling_shutter: bool,
    pub(crate) render: fn(&Render, Frames) -> Result<String>,
    pub(crate) bench: fn(&Bench) -> Result<()>,
    pub(crate) tradeoff: fn(&Tradeoff) -> Result<Vec<Outcome>>,
    /// The default frame every GPU setting of `splat tradeoff` is timed beside.
    pub(crate) tradeoff_pace: for<'a> fn(&Tradeoff<'a>) -> Result<Box<dyn PaceFrame + 'a>>,
    pub(crate) fit: Option<fn(&Fit) -> Result<()>>,
    /// Its parameters' fields (name, words): the groups `splat fit --freeze` names.
    pub(crate) param_fields: &'static [(&'static str, usize)],
    /// The effects a render with this instance simulates (`splat render --explain`).
    pub(crate) effects: fn(&Camera, &RenderOptions) -> Effects,
}

impl Instance {
    /// A method that renders (its parameters read from a PLY scene's Gaussians).
    pub fn of<M: SplatMethod>() -> Instance
    where
        M::Params: FromStored,
    {
        Instance {
            source: M::SOURCE,
            generic_camera: M::GENERIC_CAMERA,
            rolling_shutter: M::ROLLING_SHUTTER,
            render: |r, each| r.run::<M>(each),
            bench: |b| b.run::<M>(),
            tradeoff: |t| t.run::<M>(),
            tradeoff_pace: |t| t.pace::<M>(),
            fit: None,
            param_fields: M::PARAM_FIELDS,
            effects: Effects::of::<M>,
        }
    }

    /// A method that also trains (`splat fit`, written back as PLY Gaussians).
    pub fn trainable<M: Trainable>() -> Instance
    where
        M::Params: FromStored + ToStored,
    {
        Instance {
            fit: Some(|f| f.run::<M>()),
            ..Instance::of::<M>()
        }
    }
}

impl Method {
    pub fn new(name: &'static str, help: &'static str, instance: Instance) -> Method {
        Method::per_sh_degree(name, help, vec![instance])
    }

    /// A method compiled once per SH degree: `instances[k]` for scenes of degree k, so a
    /// low-degree scene evaluates no higher-order terms.
    pub fn per_sh_degree(
        name: &'static str,
        help: &'static str,
        instances: Vec<Instance>,
    ) -> Method {
        assert!(!instances.is_empty(), "{name}: at least one instance");
        Method {
            name,
            help,
            instances,
            rolling_shutter: None,
            exact: false,
            not_gaussians: None,
            antialiased: false,
        }
    }

    /// The instance that renders cameras with a rolling shutter (the others keep theirs).
    pub fn with_rolling_shutter(self, instance: Instance) -> Method {
        assert!(
            instance.rolling_shutter,
            "{}: not a rolling-shutter instance",
            self.name
        );
        Method {
            rolling_shutter: Some(instance),
            ..self
        }
    }

    /// Marks the method as the exact one (the accuracy reference of the evaluation-model
    /// knob of `splat tradeoff`).
    pub fn exact(self) -> Method {
        Method {
            exact: true,
            ..self
        }
    }

    /// Says what its primitives are, where they are not Gaussians (see `not_gaussians`).
    pub fn primitives(self, what: &'static str) -> Method {
        Method {
            not_gaussians: Some(what),
            ..self
        }
    }

    /// Marks the method as rendering antialiased (see `antialiased`).
    pub fn antialiased(self) -> Method {
        Method {
            antialiased: true,
            ..self
        }
    }

    /// A note where `cloud` was trained antialiased and `method` is not (or the reverse).
    pub(crate) fn note_antialiasing(&self, cloud: &GaussianCloud) {
        if cloud.antialiased && !self.antialiased {
            println!(
                "note: the scene was trained antialiased (its file says so); --method 3dgs-aa renders it as trained"
            );
        }
    }

    /// The instance for a scene of SH degree `degree` seen by `camera`: the rolling-shutter
    /// one when the camera moves during its readout.
    pub(crate) fn instance(&self, degree: u32, camera: &Camera) -> &Instance {
        match &self.rolling_shutter {
            Some(rolling) if camera.has_rolling_shutter() => rolling,
            _ => {
                let last = self.instances.len() - 1;
                &self.instances[(degree as usize).min(last)]
            }
        }
    }

    /// The full instance (the highest degree).
    pub(crate) fn full(&self) -> &Instance {
        &self.instances[self.instances.len() - 1]
    }
}

/// Refuses a camera `method` cannot render (its model, a rolling shutter), by the names the
/// user typed, suggesting the methods that can.
pub(crate) fn check_camera(method: &Method, methods: &[Method], camera: &Camera) -> Result<()> {
    let renders = |m: &Method| {
        let i = m.instance(u32::MAX, camera); // every degree renders the same cameras
        (camera.model == CameraModel::Pinhole || i.generic_camera)
            && (!camera.has_rolling_shutter() || i.rolling_shutter)
    };
    if renders(method) {
        return Ok(());
    }
    let can: Vec<String> = methods
        .iter()
        .filter(|m| renders(m))
        .map(|m| format!("--method {}", m.name))
        .collect();
    let hint = match can.is_empty() {
        true => String::new(),
        false => format!(": use {}", can.join(" or ")),
    };
    let model = camera.model;
    match camera.model == CameraModel::Pinhole || method.instance(u32::MAX, camera).generic_camera {
        true => bail!(
            "{} renders global shutters only, and the camera moves during its readout (shutter_turn, shutter_shift){hint}",
            method.name
        ),
        false => bail!(
            "{} renders with a pinhole camera only, and the camera is {model}{hint}",
            method.name
        ),
    }
}

/// The method called `name`.
pub(crate) fn find<'m>(methods: &'m [Method], name: &str) -> Result<&'m Method> {
    match methods.iter().find(|m| m.name == name) {
        Some(m) => Ok(m),
        None => {
            let names: Vec<&str> = methods.iter().map(|m| m.name).collect();
            bail!(
                "unknown method `{name}` (this command offers {})",
                names.join(", ")
            )
        }
    }
}
