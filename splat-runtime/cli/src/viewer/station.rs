//! The one renderer every tab of `splat view` shares: the scene is uploaded once per setting
//! (and per version of a scene in training) and one renderer draws the frames the tabs ask
//! for, in turn. The settings (method, SH degree, the knobs of `splat tradeoff`, the output
//! shown) are the server's, shared by every tab: a change made in one tab shows in all.

use crate::methods::{self, Method};
use crate::render::{self, Render};
use anyhow::{Result, anyhow, bail};
use serde::{Deserialize, Serialize};
use splat_runtime::blend::Blend;
use splat_runtime::gpu::Gpu;
use splat_runtime::io::ply::GaussianCloud;
use splat_runtime::{Camera, Frame, RenderOptions};
use std::borrow::Cow;
use std::cell::RefCell;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{SyncSender, sync_channel};
use std::sync::{Arc, Condvar, Mutex};

/// What a frame shows.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Output {
    Rgb,
    Alpha,
    Depth,
}

/// The knobs a tab turns, as the page sends and shows them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    pub method: String,
    /// At most the scene's.
    pub sh_degree: u32,
    /// Blend at most this many primitives per tile (`None`: all).
    pub p_max: Option<usize>,
    /// The transmittance a pixel stops at ([`Blend::t_min`]).
    pub t_min: f32,
    /// Pairs with less alpha are skipped ([`Blend::alpha_min`]).
    pub alpha_min: f32,
    /// How the per-pixel state is stored (a precision's name: f32, f16, unorm16, unorm8).
    pub precision: String,
    /// How the shade data is stored between the preprocess and the blend (CPU only).
    pub shade_precision: String,
    pub output: Output,
}

impl Settings {
    /// The defaults of `splat render` for `method` and a scene of SH degree `sh_degree`.
    pub fn new(method: &str, sh_degree: u32) -> Settings {
        let opts = RenderOptions::default();
        Settings {
            method: method.to_string(),
            sh_degree,
            p_max: opts.p_max,
            t_min: opts.blend.t_min,
            alpha_min: opts.blend.alpha_min,
            precision: opts.precision.name().to_string(),
            shade_precision: opts.shade_precision.name().to_string(),
            output: Output::Rgb,
        }
    }

    /// These settings with the fields of `change` (a JSON object, some of the fields) in
    /// place of theirs, checked.
    fn changed(
        &self,
        change: &serde_json::Value,
        methods: &[Method],
        most_degree: u32,
    ) -> Result<Settings> {
        let mut merged = serde_json::to_value(self)?;
        let (Some(fields), Some(into)) = (change.as_object(), merged.as_object_mut()) else {
            bail!("settings are a JSON object of the fields to change");
        };
        for (k, v) in fields {
            into.insert(k.clone(), v.clone());
        }
        let new: Settings = serde_json::from_value(merged).map_err(|e| anyhow!("settings: {e}"))?;
        methods::find(methods, &new.method)?;
        if new.sh_degree > most_degree {
            bail!(
                "SH degree {} is past the scene's {most_degree}",
                new.sh_degree
            );
        }
        if new.p_max == Some(0) {
            bail!("p_max must be at least 1 (or null for every primitive)");
        }
        for (name, v) in [("t_min", new.t_min), ("alpha_min", new.alpha_min)] {
            if !(0.0..1.0).contains(&v) {
                bail!("{name} {v} is outside [0, 1)");
            }
        }
        new.options(false)?;
        Ok(new)
    }

    /// The render options these settings stand for; `alpha` asks for the alpha output too.
    pub fn options(&self, alpha: bool) -> Result<RenderOptions> {
        let precision = |name: &str| {
            render::parse_precision(name).map_err(|e| anyhow!("precision `{name}`: {e}"))
        };
        Ok(RenderOptions {
            p_max: self.p_max,
            alpha: alpha || self.output == Output::Alpha,
            depth: self.output == Output::Depth,
            blend: Blend {
                t_min: self.t_min,
                alpha_min: self.alpha_min,
            },
            precision: precision(&self.precision)?,
            shade_precision: precision(&self.shade_precision)?,
            ..Default::default()
        })
    }
}

/// A frame rendered for a tab, with what made it.
pub struct Rendered {
    pub frame: Frame,
    pub settings: Settings,
    /// What `splat render --explain` says of it: the effects simulated and their kernels.
    pub explain: String,
    /// Where it ran ("the CPU", "GPU, <adapter>").
    pub place: String,
    /// Which version of the scene it shows ([`Station::replace`] counts them).
    pub scene_version: u64,
}

/// A camera a tab waits on a frame of.
struct Ticket {
    camera: Camera,
    reply: SyncSender<Result<Rendered>>,
}

struct State {
    settings: Settings,
    cloud: Arc<GaussianCloud>,
    /// Counts the scene's replacements.
    scene_version: u64,
    /// Counts changes of the settings and the scene: a renderer built before one stops.
    generation: u64,
    queue: VecDeque<Ticket>,
}

pub struct Station<'a> {
    methods: &'a [Method],
    gpu: Option<&'a Gpu>,
    /// Render the alpha output with every frame (to composite views on a background).
    alpha: bool,
    state: Mutex<State>,
    /// Signalled when a camera is queued, the settings or the scene change, or the station
    /// closes.
    asked: Condvar,
    closed: AtomicBool,
}

impl<'a> Station<'a> {
    pub fn new(
        methods: &'a [Method],
        cloud: GaussianCloud,
        gpu: Option<&'a Gpu>,
        settings: Settings,
        alpha: bool,
    ) -> Station<'a> {
        Station {
            methods,
            gpu,
            alpha,
            state: Mutex::new(State {
                settings,
                cloud: Arc::new(cloud),
                scene_version: 0,
                generation: 0,
                queue: VecDeque::new(),
            }),
            asked: Condvar::new(),
            closed: AtomicBool::new(false),
        }
    }

    /// Shows `cloud` from now on (a scene in training, as it is now).
    pub fn replace(&self, cloud: GaussianCloud) {
        let mut state = self.lock();
        state.cloud = Arc::new(cloud);
        state.scene_version += 1;
        state.generation += 1;
        self.asked.notify_all();
    }

    pub fn scene_version(&self) -> u64 {
        self.lock().scene_version
    }

    /// Ends [`Station::run`] and, as they notice ([`Station::closed`]), the server's loops.
    pub fn close(&self) {
        self.closed.store(true, Ordering::Relaxed);
        let _state = self.lock();
        self.asked.notify_all();
    }

    pub fn closed(&self) -> bool {
        self.closed.load(Ordering::Relaxed)
    }

    pub fn settings(&self) -> Settings {
        self.lock().settings.clone()
    }

    /// Changes the settings by `change` (some of their fields, as JSON); frames asked from now
    /// on use them. Refused, with the settings left as they were, when a field is not valid.
    pub fn change(&self, change: &serde_json::Value) -> Result<Settings> {
        let mut state = self.lock();
        let most_degree = state.cloud.sh_degree;
        let new = state.settings.changed(change, self.methods, most_degree)?;
        if new != state.settings {
            state.settings = new.clone();
            state.generation += 1;
            self.asked.notify_all();
        }
        Ok(new)
    }

    /// Renders `camera` with the current settings, after the frames other tabs asked first.
    pub fn render(&self, camera: Camera) -> Result<Rendered> {
        let (reply, frame) = sync_channel(1);
        {
            let mut state = self.lock();
            if self.closed() {
                bail!("the viewer is closing");
            }
            state.queue.push_back(Ticket { camera, reply });
        }
        self.asked.notify_all();
        frame.recv().map_err(|_| anyhow!("the renderer stopped"))?
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        // A tab that panicked holding the lock leaves the state whole: every change is one
        // assignment.
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Renders the frames tabs ask for until the station closes: one renderer and one upload
    /// of the scene serve every frame until the settings or the scene change (or a camera
    /// needs another of the method's instances).
    pub fn run(&self) {
        loop {
            let (settings, scene, generation, first) = {
                let mut state = self.lock();
                while state.queue.is_empty() && !self.closed() {
                    state = self.asked.wait(state).unwrap_or_else(|e| e.into_inner());
                }
                if self.closed() {
                    // Whoever still waits hears so (their tickets dropped).
                    state.queue.clear();
                    return;
                }
                let scene = (Arc::clone(&state.cloud), state.scene_version);
                let first = state.queue[0].camera;
                (state.settings.clone(), scene, state.generation, first)
            };
            if let Err(e) = self.serve_run(&settings, &scene, generation, &first) {
                // An error before any frame (the renderer for these settings, or a camera the
                // method cannot render) answers the first camera waiting.
                if let Some(ticket) = self.lock().queue.pop_front() {
                    ticket.reply.send(Err(e)).ok();
                }
            }
        }
    }

    /// Renders queued cameras with one renderer built for `settings` and `first`'s instance
    /// of the method, while they last; an error before the first frame is returned.
    fn serve_run(
        &self,
        settings: &Settings,
        (cloud, scene_version): &(Arc<GaussianCloud>, u64),
        generation: u64,
        first: &Camera,
    ) -> Result<()> {
        let method = methods::find(self.methods, &settings.method)?;
        methods::check_camera(method, self.methods, first)?;
        let opts = settings.options(self.alpha)?;
        let cloud = lower_degree(cloud, settings.sh_degree);
        let instance = method.instance(cloud.sh_degree, first);
        // The camera being rendered and the tab waiting on it.
        type InFlight = Option<(Camera, SyncSender<Result<Rendered>>)>;
        let in_flight: RefCell<InFlight> = RefCell::new(None);
        // The next camera this renderer draws: waits for one while the settings hold; none
        // once they change or the next needs another renderer.
        let cameras = || {
            let mut state = self.lock();
            loop {
                if state.generation != generation || self.closed() {
                    return None;
                }
                if let Some(next) = state.queue.front() {
                    let same =
                        std::ptr::eq(method.instance(cloud.sh_degree, &next.camera), instance);
                    if !same || methods::check_camera(method, self.methods, &next.camera).is_err() {
                        return None;
                    }
                    let ticket = state.queue.pop_front()?;
                    *in_flight.borrow_mut() = Some((ticket.camera, ticket.reply));
                    return Some(ticket.camera);
                }
                state = self.asked.wait(state).unwrap_or_else(|e| e.into_inner());
            }
        };
        let place = render::place(self.gpu, false);
        let task = Render {
            cloud: &cloud,
            cameras: &cameras,
            opts: &opts,
            gpu: self.gpu,
            hardware: false,
        };
        let result = (instance.render)(&task, &mut |frame| {
            if let Some((camera, reply)) = in_flight.borrow_mut().take() {
                let rendered = Rendered {
                    frame,
                    settings: settings.clone(),
                    explain: (instance.effects)(&camera, &opts).to_string(),
                    place: place.clone(),
                    scene_version: *scene_version,
                };
                reply.send(Ok(rendered)).ok();
            }
            Ok(())
        });
        match (result, in_flight.borrow_mut().take()) {
            // The frame in flight failed: its tab hears why; the next run starts afresh.
            (Err(e), Some((_, reply))) => {
                reply.send(Err(e)).ok();
                Ok(())
            }
            (result, _) => result.map(|_| ()),
        }
    }
}

/// `cloud` at SH degree `degree` (below its own: the higher terms left out).
fn lower_degree(cloud: &GaussianCloud, degree: u32) -> Cow<'_, GaussianCloud> {
    if degree >= cloud.sh_degree {
        return Cow::Borrowed(cloud);
    }
    let kept = ((degree + 1) * (degree + 1)) as usize;
    let mut lower = cloud.clone();
    lower.sh_degree = degree;
    for g in &mut lower.gaussians {
        g.sh[kept..].fill(Default::default());
    }
    Cow::Owned(lower)
}
