//! `splat fit --view`: `splat view`'s page served while the run trains. The run hands its
//! scene to the page's renderer every `--view-every` steps (`FitOptions::share_every`), and
//! its status (step, loss, test PSNR, primitives) after every step; a tab's pause holds the
//! run between two steps.

use crate::commands::view::{ServeArgs, intro};
use crate::methods::Method;
use crate::viewer::{self, Live, Scene, Settings, Station};
use anyhow::Result;
use splat_runtime::glam::Vec3;
use splat_runtime::gpu::Gpu;
use splat_runtime::io::ply::{GaussianCloud, ToStored};
use splat_runtime::train::fit::StepReport;
use splat_runtime::train::{Checkpoint, Trainable};
use splat_runtime::{Flat, SplatMethod};
use std::net::TcpListener;

/// The page of a run, and the server that serves it.
pub struct FitView<'a> {
    scene: Scene<'a>,
    listener: TcpListener,
    token: Option<String>,
}

/// The scene a run's parameter words stand for (an INRIA PLY's Gaussians, as the run writes).
pub fn cloud<M: SplatMethod>(words: &[f32]) -> GaussianCloud
where
    M::Params: ToStored,
{
    GaussianCloud::new(
        3,
        (words.chunks_exact(M::Params::LEN))
            .map(|w| M::Params::read_words(w).to_stored())
            .collect(),
    )
}

impl<'a> FitView<'a> {
    /// Listens for the page of a run of `method` from `state`, saying where.
    pub fn new<M: Trainable>(
        methods: &'a [Method],
        method: &str,
        gpu: Option<&'a Gpu>,
        state: &Checkpoint,
        serve: &ServeArgs,
    ) -> Result<FitView<'a>>
    where
        M::Params: ToStored,
    {
        let cloud = cloud::<M>(&state.params);
        let settings = Settings::new(method, cloud.sh_degree);
        let intro = intro(methods, &cloud, &[]);
        let (listener, token) = serve.listen("splat fit --view", method, cloud.gaussians.len())?;
        let station = Station::new(methods, cloud, gpu, settings, false);
        let scene = Scene {
            station,
            views: vec![],
            background: Vec3::ZERO,
            intro,
            live: Some(Live::new(state.steps, state.step)),
        };
        Ok(FitView {
            scene,
            listener,
            token,
        })
    }

    /// Serves the page until [`FitView::close`].
    pub fn serve(&self) -> Result<()> {
        viewer::serve(&self.listener, &self.scene, self.token.as_deref())
    }

    /// Takes in a step's report: its status, and its scene where it has one; then holds the
    /// run while a tab has it paused (or until `stop` says the run is asked to end).
    pub fn step<M: SplatMethod>(&self, r: &StepReport, stop: &dyn Fn() -> bool)
    where
        M::Params: ToStored,
    {
        let live = self.scene.live.as_ref().expect("a run's view has its run");
        let psnr = r.evaluation.as_ref().map(|e| e.psnr);
        live.step(r.step + 1, r.loss.loss, r.primitives, psnr);
        if let Some(words) = r.scene {
            self.scene.station.replace(cloud::<M>(words));
        }
        live.wait_while_paused(stop);
    }

    pub fn close(&self) {
        self.scene.station.close();
    }
}
