//! Where a command's camera comes from: a camera file, or one view of a dataset (the posed
//! pictures `splat fit` trains on), so a trained scene renders from its own views.

use anyhow::{Result, bail};
use splat_runtime::Camera;
use splat_runtime::io::camera as camera_io;
use splat_runtime::io::dataset::{self, Shot};
use std::path::PathBuf;
use std::str::FromStr;

#[derive(clap::Args)]
pub struct CameraArgs {
    /// Camera JSON, or a dataset folder (Blender, nerfstudio or COLMAP, as `splat fit` reads
    /// them) whose view --view to take (default: the built-in view at --width x --height).
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// With a dataset as --camera: which of its views, `test/K` or `train/K` (K from 0; the
    /// splits `splat fit` uses) [default: test/0].
    #[arg(long, requires = "camera")]
    pub view: Option<ViewPick>,
}

/// A view of a dataset: its split and its index there.
#[derive(Clone, Copy, Debug)]
pub struct ViewPick {
    test: bool,
    index: usize,
}

impl FromStr for ViewPick {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let parsed = s.split_once('/').and_then(|(split, k)| {
            let test = match split {
                "test" => true,
                "train" => false,
                _ => return None,
            };
            Some(ViewPick {
                test,
                index: k.parse().ok()?,
            })
        });
        parsed.ok_or_else(|| "expected test/K or train/K, K a view's number from 0".into())
    }
}

impl std::fmt::Display for ViewPick {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        let split = if self.test { "test" } else { "train" };
        write!(f, "{split}/{}", self.index)
    }
}

/// The camera a command was given, if any.
pub struct Given {
    pub camera: Camera,
    /// The dataset's picture when the camera is one of its views.
    pub shot: Option<Shot>,
}

impl CameraArgs {
    /// The camera of `--camera` (a camera file, or a dataset's view `--view`), or `None`.
    pub fn read(&self) -> Result<Option<Given>> {
        let Some(path) = &self.camera else {
            return Ok(None);
        };
        if !path.is_dir() {
            if let Some(pick) = self.view {
                bail!(
                    "--view {pick} picks a view of a dataset, and {} is not a dataset folder",
                    path.display()
                );
            }
            let camera = camera_io::read(path)?;
            return Ok(Some(Given { camera, shot: None }));
        }
        let pick = self.view.unwrap_or(ViewPick {
            test: true,
            index: 0,
        });
        let shots = dataset::read_shots(path)?;
        let (name, mut split) = match pick.test {
            true => ("test", shots.test),
            false => ("train", shots.train),
        };
        let n = split.len();
        if pick.index >= n {
            bail!(
                "{}: there is no view {pick}: the dataset has {n} {name} views{}",
                path.display(),
                match n {
                    0 => String::new(),
                    n => format!(" ({name}/0 to {name}/{})", n - 1),
                }
            );
        }
        let shot = split.swap_remove(pick.index);
        Ok(Some(Given {
            camera: shot.camera,
            shot: Some(shot),
        }))
    }
}
