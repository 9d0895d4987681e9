//! `splat view [PATH]`: serves a scene (`crate::source`: a PLY, a `splat fit` output folder,
//! the built-in one, or a dataset's views with `--scene`) to a browser page that flies around it, each frame
//! rendered by the method on the GPU (or the CPU) as the page's camera moves (`crate::viewer`).

use crate::methods::{self, Method};
use crate::orbit::Orbit;
use crate::source::{Source, SourceArgs};
use crate::view::Split;
use crate::{Backend, pick_gpu, viewer};
use anyhow::Result;
use splat_runtime::glam::Vec3;
use splat_runtime::io::dataset;
use splat_runtime::io::ply::GaussianCloud;
use splat_runtime::precision::Precision;
use std::net::{IpAddr, TcpListener};

#[derive(clap::Args)]
pub struct ViewArgs {
    #[command(flatten)]
    pub source: SourceArgs,
    #[arg(long)]
    pub method: String,
    /// With a dataset: which of its views the page offers (the splits `splat fit` uses).
    #[arg(long, value_enum, default_value_t = Split::Test)]
    pub split: Split,
    /// With a dataset: compare on white instead of black (as `splat fit --white`).
    #[arg(long)]
    pub white: bool,
    #[command(flatten)]
    pub serve: ServeArgs,
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
}

/// Where the page is served.
#[derive(clap::Args)]
pub struct ServeArgs {
    /// The address the page is served on. Anything but the loopback opens the scene to the
    /// network: the page then asks for a random token, printed in its URL.
    #[arg(long, default_value = "127.0.0.1")]
    pub host: IpAddr,
    /// The page's port (the next free one if taken; 0 for any).
    #[arg(long, default_value_t = 8123)]
    pub port: u16,
}

impl ServeArgs {
    /// Listens where asked and prints the page's URL (with its token, when open to the
    /// network), for `what` showing `method`'s `primitives`.
    pub fn listen(
        &self,
        what: &str,
        method: &str,
        primitives: usize,
    ) -> Result<(TcpListener, Option<String>)> {
        let token = match self.host.is_loopback() {
            true => None,
            false => Some(viewer::new_token()?),
        };
        let listener = viewer::bind(self.host, self.port)?;
        let address = listener.local_addr()?;
        let url = match &token {
            Some(t) => format!("http://{address}/?token={t}"),
            None => format!("http://{address}/"),
        };
        println!("{what}: {url} ({method}, {primitives} Gaussians; Ctrl-C ends it)");
        if token.is_some() {
            eprintln!(
                "listening on {}: anyone who can reach it and has the token sees the scene",
                self.host
            );
        }
        Ok((listener, token))
    }
}

pub(crate) fn view_cmd(args: &ViewArgs, methods: &[Method]) -> Result<()> {
    let method = methods::find(methods, &args.method)?;
    let Source { cloud, views, name } = args.source.read(Some(args.split))?;
    let gpu = pick_gpu(args.backend)?;
    let background = if args.white { Vec3::ONE } else { Vec3::ZERO };
    let settings = viewer::Settings::new(method.name, cloud.sh_degree);
    let intro = intro(methods, &cloud, &views);
    let primitives = cloud.gaussians.len();
    let station = viewer::Station::new(methods, cloud, gpu.as_ref(), settings, args.white);
    let scene = viewer::Scene {
        station,
        views,
        background,
        intro,
        live: None,
    };
    let what = format!("splat view of {name}");
    let (listener, token) = args.serve.listen(&what, method.name, primitives)?;
    viewer::serve(&listener, &scene, token.as_deref())
}

/// What a page is told on connecting: the scene, the views it can snap to, the choices of
/// each knob.
pub(crate) fn intro(
    methods: &[Method],
    cloud: &GaussianCloud,
    views: &[dataset::Shot],
) -> serde_json::Value {
    let cameras: Vec<_> = views.iter().map(|s| s.camera).collect();
    let means: Vec<_> = cloud.gaussians.iter().map(|g| g.mean).collect();
    let names: Vec<String> = (views.iter().enumerate())
        .map(|(k, s)| match s.path.file_name() {
            Some(n) => format!("{k}: {}", n.to_string_lossy()),
            None => k.to_string(),
        })
        .collect();
    serde_json::json!({
        "primitives": cloud.gaussians.len(),
        "sh_degree": cloud.sh_degree,
        "views": names,
        "orbit": Orbit::of(&cameras, &means).json(),
        "methods": methods.iter().map(|m| m.name).collect::<Vec<_>>(),
        "precisions": Precision::ALL.iter().map(|p| p.name()).collect::<Vec<_>>(),
    })
}
