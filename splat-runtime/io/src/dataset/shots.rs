//! The dataset model: a posed picture before its pixels are read ([`Shot`]), a dataset's
//! views before and after loading ([`Shots`], [`Dataset`]), its initial points ([`Point`]),
//! and the camera of a picture stored at another size.

use super::error::{DatasetError, field, image_size};
use crate::picture::{Footprint, Picture, View};
use crate::undistort::{Lens, Undistortion};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use splat_core::types::Camera;
use std::path::{Path, PathBuf};

/// A posed picture before its pixels are read: the file, and the camera fitted to its size
/// (from the file's header). What rendering a view of a dataset needs.
#[derive(Clone, Debug)]
pub struct Shot {
    pub path: PathBuf,
    /// The view's camera: fitted to the picture's size, divided by `downscale` (and cut from
    /// the picture through its lens, [`Shot::undistortion`]).
    pub camera: Camera,
    /// The picture is box-averaged by this factor on load ([`Shot::downscaled`]; 1: used as
    /// stored).
    pub downscale: u32,
    /// The dataset's picture folder that `path` lies in: COLMAP's `images` (whose names may
    /// have folders of their own), the picture's own folder in the other layouts. Copies made
    /// smaller lie at the same place in `<folder>_<factor>`.
    pub folder: PathBuf,
    /// The lens distortion taken out of the picture on load, and where the view lies in it
    /// (`None`: the picture, after any downscale, is the view).
    pub undistortion: Option<Undistortion>,
}

impl Shot {
    /// A shot of the picture at `path`, used at its size, seen by `camera`.
    pub fn new(path: PathBuf, camera: Camera) -> Shot {
        let folder = path.parent().unwrap_or(Path::new("")).to_path_buf();
        Shot::in_folder(folder, path, camera)
    }

    /// [`Shot::new`] for a picture somewhere inside the dataset's picture folder `folder`
    /// ([`Shot::folder`]).
    pub fn in_folder(folder: PathBuf, path: PathBuf, camera: Camera) -> Shot {
        Shot {
            path,
            camera,
            downscale: 1,
            folder,
            undistortion: None,
        }
    }

    /// This shot with `lens`'s distortion taken out of its picture on load, its camera the
    /// pinhole view cut from it ([`Undistortion::new`], whose error this returns).
    pub fn through(self, lens: Lens) -> Result<Shot, String> {
        let cut = Undistortion::new(self.picture_camera(), lens)?;
        Ok(Shot {
            camera: cut.view(),
            undistortion: Some(cut),
            ..self
        })
    }

    /// The camera of the picture as it is read (after any downscale): the view's camera unless
    /// the view is cut from it through a lens.
    fn picture_camera(&self) -> Camera {
        self.undistortion.map_or(self.camera, |cut| cut.picture)
    }

    /// The view `factor` times smaller on each side, as gsplat's `data_factor`: from the copy
    /// of the picture in the sibling folder `<folder>_<factor>` where there is one (COLMAP's
    /// and nerfstudio's `images_4`; it must be that size, give or take a pixel of rounding),
    /// else box-averaged over `factor` x `factor` blocks on load, the right and bottom pixels
    /// that fill no block dropped. The intrinsics scale with the size; a view cut from its
    /// picture through a lens is cut again from the smaller picture.
    pub fn downscaled(self, factor: u32) -> Result<Shot, DatasetError> {
        if factor <= 1 {
            return Ok(self);
        }
        let Some(cut) = self.undistortion else {
            return self.picture_downscaled(factor);
        };
        let picture = Shot {
            camera: cut.picture,
            undistortion: None,
            ..self
        };
        let small = picture.picture_downscaled(factor)?;
        let path = small.path.clone();
        small.through(cut.lens).map_err(|p| field(&path, "lens", p))
    }

    /// [`Shot::downscaled`] for a shot whose view is its picture.
    fn picture_downscaled(self, factor: u32) -> Result<Shot, DatasetError> {
        let full = self.camera.size;
        let want = full / factor as f32;
        if let Some((copies, copy)) = self.copy_at(factor) {
            let (width, height) = image_size(&copy)?;
            let size = Vec2::new(width as f32, height as f32);
            let camera = rescaled(&self.camera, width, height)
                .filter(|_| (size - want).abs().max_element() <= 1.0)
                .ok_or_else(|| {
                    let problem = format!(
                        "{width}x{height} is not {} downscaled {factor}x (about {}x{})",
                        self.path.display(),
                        want.x.round(),
                        want.y.round()
                    );
                    field(&copy, "size", problem)
                })?;
            return Ok(Shot::in_folder(copies, copy, camera));
        }
        let size = want.floor();
        if size.min_element() < 1.0 {
            let problem = format!(
                "{}x{} pixels cannot be downscaled {factor}x",
                full.x, full.y
            );
            return Err(field(&self.path, "size", problem));
        }
        let camera = Camera {
            focal: self.camera.focal / factor as f32,
            principal: self.camera.principal / factor as f32,
            size,
            ..self.camera
        };
        Ok(Shot {
            camera,
            downscale: factor,
            ..self
        })
    }

    /// The picture's copy at its place in `<folder>_<factor>` beside its picture folder
    /// ([`Shot::folder`]), if there is one: `images_4/x.jpg` for `images/x.jpg`, and
    /// `images_4/cam0/x.jpg` for COLMAP's `images/cam0/x.jpg`. Only there: a sibling dataset
    /// (`lego_2` beside `lego`) is never mistaken for copies. Returns the copies' folder and
    /// the copy.
    fn copy_at(&self, factor: u32) -> Option<(PathBuf, PathBuf)> {
        let name = format!("{}_{factor}", self.folder.file_name()?.to_str()?);
        let place = self.path.strip_prefix(&self.folder).ok()?;
        // A name such as `../x.jpg` has no place among the copies.
        let plain = |c: std::path::Component| matches!(c, std::path::Component::Normal(_));
        if !place.components().all(plain) {
            return None;
        }
        let copies = self.folder.with_file_name(name);
        let copy = copies.join(place);
        copy.is_file().then_some((copies, copy))
    }

    /// The view: the picture decoded, downscaled, cut through its lens and composited on
    /// `background`.
    pub fn load(&self, background: Vec3) -> Result<View, DatasetError> {
        let picture = Picture::read(&self.path)?;
        // Checked before averaging: a picture narrower than a block has nothing to average.
        let (f, camera) = (self.downscale, self.picture_camera().size);
        let (w, h) = (picture.width, picture.height);
        if Vec2::new((w / f) as f32, (h / f) as f32) != camera {
            let downscaled = match f {
                1 => String::new(),
                f => format!(" ({}x{} downscaled {f}x)", w / f, h / f),
            };
            return Err(field(
                &self.path,
                "size",
                format!(
                    "decodes to {w}x{h} pixels{downscaled}, but its camera is {}x{} (from its header's size when the dataset was read)",
                    camera.x, camera.y
                ),
            ));
        }
        let picture = match f {
            1 => picture,
            f => picture.downscaled(f),
        };
        let picture = match &self.undistortion {
            None => picture,
            Some(cut) => cut
                .apply(&picture)
                .map_err(|p| field(&self.path, "lens", p))?,
        };
        Ok(picture.view(self.path.display().to_string(), self.camera, background))
    }
}

/// Each of `shots` `factor` times smaller on each side ([`Shot::downscaled`]; their copies'
/// headers read in parallel).
pub fn downscaled(shots: Vec<Shot>, factor: u32) -> Result<Vec<Shot>, DatasetError> {
    (shots.into_par_iter())
        .map(|shot| shot.downscaled(factor))
        .collect()
}

/// A dataset's posed pictures, read from its files without decoding a pixel.
#[derive(Clone, Debug)]
pub struct Shots {
    pub train: Vec<Shot>,
    pub test: Vec<Shot>,
    /// As [`Dataset::points`].
    pub points: Vec<Point>,
}

impl Shots {
    /// Every picture decoded (in parallel, so with several broken ones, which the error names
    /// may vary) and composited on `background`.
    pub fn load(self, background: Vec3) -> Result<Dataset, DatasetError> {
        self.load_counted(background, &|| {})
    }

    /// [`Shots::load`], calling `loaded` as each picture is done (for a progress bar).
    pub fn load_counted(
        self,
        background: Vec3,
        loaded: &(dyn Fn() + Sync),
    ) -> Result<Dataset, DatasetError> {
        let load = |shots: &[Shot]| {
            (shots.par_iter())
                .map(|shot| {
                    let view = shot.load(background);
                    loaded();
                    view
                })
                .collect::<Result<Vec<_>, _>>()
        };
        Ok(Dataset {
            train: load(&self.train)?,
            test: load(&self.test)?,
            points: self.points,
        })
    }

    /// What loading every view takes in host memory, from the pictures' headers (read in
    /// parallel): the bytes the views hold, summed, and the most one picture takes to decode.
    pub fn footprint(&self) -> Result<Footprint, DatasetError> {
        let shots: Vec<&Shot> = self.train.iter().chain(&self.test).collect();
        let each = (shots.par_iter())
            .map(|shot| {
                let size = shot.camera.size;
                Picture::footprint(&shot.path, size.x as u64 * size.y as u64)
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Footprint {
            held: each.iter().map(|f| f.held).sum(),
            decoding: each.iter().map(|f| f.decoding).max().unwrap_or(0),
            largest: each.iter().map(|f| f.largest).max().unwrap_or(0),
        })
    }

    /// Every view `factor` times smaller on each side ([`downscaled`]).
    pub fn downscaled(self, factor: u32) -> Result<Shots, DatasetError> {
        Ok(Shots {
            train: downscaled(self.train, factor)?,
            test: downscaled(self.test, factor)?,
            points: self.points,
        })
    }

    /// Every 8th of `shots` (from the first) held out for testing, as 3DGS does.
    pub(crate) fn every_8th_held_out(shots: Vec<Shot>, points: Vec<Point>) -> Shots {
        let (mut train, mut test) = (vec![], vec![]);
        for (k, shot) in shots.into_iter().enumerate() {
            match k % 8 {
                0 => test.push(shot),
                _ => train.push(shot),
            }
        }
        Shots {
            train,
            test,
            points,
        }
    }
}

/// The training and held-out views of a scene.
#[derive(Clone, Debug)]
pub struct Dataset {
    pub train: Vec<View>,
    pub test: Vec<View>,
    /// Points to start training from (COLMAP's sparse points); empty when the layout has
    /// none (Blender, nerfstudio).
    pub points: Vec<Point>,
}

impl Dataset {
    /// A hash of what training reads (the views' cameras and pixels in order, the points):
    /// equal on two processes that read the same dataset, wherever it lies.
    pub fn fingerprint(&self) -> u64 {
        use std::hash::Hasher;
        let mut h = std::hash::DefaultHasher::new();
        for views in [&self.train, &self.test] {
            h.write_usize(views.len());
            views.iter().for_each(|v| v.fingerprint(&mut h));
        }
        for p in &self.points {
            (p.position.to_array().iter().chain(&p.color.to_array()))
                .for_each(|x| h.write_u32(x.to_bits()));
        }
        h.finish()
    }
}

/// A point of a dataset's initial point cloud.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    pub position: Vec3,
    /// RGB in [0, 1].
    pub color: Vec3,
}

/// `camera` for a picture of `width` x `height` pixels (a downscaled copy, as in `images_4`):
/// the focal lengths and principal point scale with the size. `None` when the aspect ratio
/// differs by more than a pixel.
pub(crate) fn rescaled(camera: &Camera, width: u32, height: u32) -> Option<Camera> {
    let size = Vec2::new(width as f32, height as f32);
    let scale = size / camera.size;
    ((camera.size.y * scale.x - size.y).abs() <= 1.0).then(|| Camera {
        focal: camera.focal * scale,
        principal: camera.principal * scale,
        size,
        ..*camera
    })
}
