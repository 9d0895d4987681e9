//! What `splat view` and `splat video` show: a PLY, a `splat fit` output folder, the built-in
//! scene, or a scene on a dataset's views (`DATASET --scene S.ply`).

use crate::scene;
use crate::view::{Downscale, Split};
use anyhow::{Result, bail};
use splat_runtime::io::dataset::{self, Shot};
use splat_runtime::io::formats::Format;
use splat_runtime::io::ply::GaussianCloud;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct SourceArgs {
    /// An INRIA PLY scene or a `splat fit` output folder (its scene.ply); with --scene, a
    /// dataset (Blender, nerfstudio or COLMAP) whose views come with it [default: the
    /// built-in scene].
    pub path: Option<PathBuf>,
    /// The scene (INRIA PLY) to show on the dataset PATH's views.
    #[arg(long, requires = "path")]
    pub scene: Option<PathBuf>,
    #[command(flatten)]
    pub downscale: Downscale,
}

/// A scene, and the dataset views it comes with (none without a dataset).
pub struct Source {
    pub cloud: GaussianCloud,
    pub views: Vec<Shot>,
    /// Where it came from, for a report.
    pub name: String,
}

impl SourceArgs {
    /// The scene and its dataset's `split` views (every view, in the order of their pictures'
    /// names, without a split).
    pub fn read(&self, split: Option<Split>) -> Result<Source> {
        let (Some(path), Some(ply)) = (&self.path, &self.scene) else {
            return Ok(match &self.path {
                Some(path) => Source {
                    cloud: read_scene(path)?,
                    views: vec![],
                    name: path.display().to_string(),
                },
                None => Source {
                    cloud: scene::planet(),
                    views: vec![],
                    name: "the built-in scene".to_string(),
                },
            });
        };
        let shots = dataset::read_shots(path)?;
        let (views, which) = match split {
            Some(split) => (split.of(shots), format!("{} ", split.name())),
            None => {
                let mut all: Vec<Shot> = shots.train.into_iter().chain(shots.test).collect();
                all.sort_by(|a, b| a.path.cmp(&b.path));
                (all, String::new())
            }
        };
        let views = dataset::downscaled(views, self.downscale.factor)?;
        if views.is_empty() {
            bail!("{}: no {which}views", path.display());
        }
        let name = format!(
            "{}, {} {which}views of {}",
            ply.display(),
            views.len(),
            path.display()
        );
        Ok(Source {
            cloud: scene::read(ply)?,
            views,
            name,
        })
    }
}

/// A PLY, or the scene.ply of a `splat fit` output folder.
fn read_scene(path: &Path) -> Result<GaussianCloud> {
    if path.is_dir() {
        let ply = path.join(crate::fit::scene_file(Format::Ply));
        if !ply.is_file() {
            bail!(
                "{} is a folder without scene.ply (what `splat fit` writes); for a dataset, \
                 give the scene with --scene",
                path.display()
            );
        }
        return scene::read(&ply);
    }
    scene::read(path)
}
