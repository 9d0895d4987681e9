//! Where a command's camera comes from: a camera file, or one view of a dataset (the posed
//! pictures `splat fit` trains on), so a trained scene renders from its own views.

use anyhow::{Result, bail};
use splat_runtime::Camera;
use splat_runtime::io::camera as camera_io;
use splat_runtime::io::dataset::{self, Shot, Shots};
use splat_runtime::io::undistort::Undistortion;
use std::path::PathBuf;
use std::str::FromStr;

#[derive(clap::Args)]
pub struct CameraArgs {
    /// Camera JSON, or a dataset folder (Blender, nerfstudio or COLMAP, as `splat fit` reads
    /// them) whose view --view to take (default: the built-in view).
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// With a dataset as --camera: which of its views, `test/K` or `train/K` (K from 0; the
    /// splits `splat fit` uses) [default: test/0].
    #[arg(long, requires = "camera")]
    pub view: Option<ViewPick>,
    #[command(flatten)]
    pub downscale: Downscale,
}

/// How much smaller than its pictures a dataset's views are taken.
#[derive(clap::Args, Clone, Copy)]
pub struct Downscale {
    /// A dataset's views N times smaller on each side (gsplat's `data_factor`): from the
    /// copies in a folder `<folder>_N` beside a picture's folder where there are some
    /// (COLMAP's and nerfstudio's `images_N`, `cam0/x.jpg` in `images_N/cam0`; `train_N` in
    /// a Blender dataset), else each
    /// picture averaged over N x N blocks as it is read; the intrinsics scale with the size.
    #[arg(long = "downscale", value_name = "N", default_value_t = 1,
          value_parser = clap::value_parser!(u32).range(1..))]
    pub factor: u32,
}

impl Downscale {
    /// How `shots` were made smaller, for a report: " (from images_4)", " (pictures
    /// averaged over 4x4 blocks)", both with counts, or nothing at full size.
    pub fn how<'a>(self, shots: impl IntoIterator<Item = &'a Shot>) -> String {
        let f = self.factor;
        let shots: Vec<&Shot> = shots.into_iter().collect();
        let all = || shots.iter().copied();
        let copies: Vec<&Shot> = all().filter(|s| s.downscale < f).collect();
        // The copies' folders, in order of first use.
        let mut folders: Vec<String> = vec![];
        for folder in copies.iter().filter_map(|s| s.folder.file_name()) {
            let folder = folder.to_string_lossy().into_owned();
            if !folders.contains(&folder) {
                folders.push(folder);
            }
        }
        let folders = folders.join(" and ");
        let averaged = format!("averaged over {f}x{f} blocks");
        match copies.len() {
            _ if f == 1 => String::new(),
            0 => format!(" (pictures {averaged})"),
            n if n == all().count() => format!(" (from {folders})"),
            n => format!(" ({n} from {folders}, {} {averaged})", all().count() - n),
        }
    }
}

/// Which of `shots` are cut from their pictures through a lens, for a report: " (the lens
/// distortion of 80 pictures taken out, 200x200 cropped to 190x190)", the sizes when they are
/// the same for all; nothing when none is.
pub fn undistorted<'a>(shots: impl IntoIterator<Item = &'a Shot>) -> String {
    let cuts: Vec<_> = shots.into_iter().filter_map(|s| s.undistortion).collect();
    let Some(first) = cuts.first() else {
        return String::new();
    };
    let sizes = |c: &Undistortion| (c.picture.size, c.size);
    let n = cuts.len();
    let plural = if n == 1 { "picture" } else { "pictures" };
    match cuts.iter().all(|c| sizes(c) == sizes(first)) {
        true => {
            let (from, to) = sizes(first);
            format!(
                " (the lens distortion of {n} {plural} taken out, {}x{} cropped to {}x{})",
                from.x, from.y, to.x, to.y
            )
        }
        false => format!(" (the lens distortion of {n} {plural} taken out)"),
    }
}

/// A dataset's held-out views or its training views, as `splat fit` splits them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Split {
    Test,
    Train,
}

impl Split {
    pub fn name(self) -> &'static str {
        match self {
            Split::Test => "test",
            Split::Train => "train",
        }
    }

    /// This split's shots of `shots`.
    pub fn of(self, shots: Shots) -> Vec<Shot> {
        match self {
            Split::Test => shots.test,
            Split::Train => shots.train,
        }
    }
}

/// A view of a dataset: its split and its index there.
#[derive(Clone, Copy, Debug)]
pub struct ViewPick {
    split: Split,
    index: usize,
}

impl FromStr for ViewPick {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let parsed = s.split_once('/').and_then(|(split, k)| {
            let split = [Split::Test, Split::Train]
                .into_iter()
                .find(|t| t.name() == split)?;
            Some(ViewPick {
                split,
                index: k.parse().ok()?,
            })
        });
        parsed.ok_or_else(|| "expected test/K or train/K, K a view's number from 0".into())
    }
}

impl std::fmt::Display for ViewPick {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        write!(f, "{}/{}", self.split.name(), self.index)
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
            if self.downscale.factor != 1 {
                bail!("--downscale applies to a dataset's views: give one with --camera DATASET");
            }
            return Ok(None);
        };
        if !path.is_dir() {
            if let Some(pick) = self.view {
                bail!(
                    "--view {pick} picks a view of a dataset, and {} is not a dataset folder",
                    path.display()
                );
            }
            if self.downscale.factor != 1 {
                bail!(
                    "--downscale applies to a dataset's views, and {} is not a dataset folder",
                    path.display()
                );
            }
            let camera = camera_io::read(path)?;
            return Ok(Some(Given { camera, shot: None }));
        }
        let pick = self.view.unwrap_or(ViewPick {
            split: Split::Test,
            index: 0,
        });
        let mut shots = pick.split.of(dataset::read_shots(path)?);
        let (n, name) = (shots.len(), pick.split.name());
        if pick.index >= n {
            let which = match n {
                0 => String::new(),
                1 => format!(" (only {name}/0)"),
                n => format!(" ({name}/0 to {name}/{})", n - 1),
            };
            bail!(
                "{}: there is no view {pick}: the dataset has {n} {name} views{which}",
                path.display()
            );
        }
        let shot = shots
            .swap_remove(pick.index)
            .downscaled(self.downscale.factor)?;
        Ok(Some(Given {
            camera: shot.camera,
            shot: Some(shot),
        }))
    }
}
