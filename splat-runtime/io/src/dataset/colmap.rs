//! COLMAP sparse models as training datasets: a folder with the model in `sparse/0/` (or
//! `sparse/`) as `cameras`, `images` and `points3D` in COLMAP's binary (`.bin`) or text
//! (`.txt`) format, and the pictures in `images/` under the names the model gives them.
//!
//! COLMAP's poses are world-to-camera in OpenCV axes, our [`Camera`] convention, so they are
//! taken as they are. SIMPLE_PINHOLE and PINHOLE cameras are pinhole cameras; OPENCV_FISHEYE,
//! SIMPLE_RADIAL_FISHEYE and RADIAL_FISHEYE are our Kannala-Brandt camera (fisheye pictures
//! train as they are). The distortion of SIMPLE_RADIAL, RADIAL, OPENCV and FULL_OPENCV cameras
//! is taken out of their pictures on load ([`crate::undistort`]). FOV and the thin-prism models
//! are refused: COLMAP's `image_undistorter` removes their distortion.
//!
//! The files are untrusted: every count in a binary file is checked against the bytes left
//! before anything is allocated, and every error names the file and the element.

use super::error::{DatasetError, field, image_size};
use super::shots::{Dataset, Point, Shot, Shots, rescaled};
use crate::undistort::Lens;
use glam::{DMat3, DQuat, DVec3, DVec4, Mat3, Vec2, Vec3, Vec4};
use rayon::prelude::*;
use splat_core::types::{Camera, CameraModel};
use std::collections::HashMap;
use std::fmt::Display;
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// COLMAP's camera models, by id.
const MODELS: [&str; 12] = [
    "SIMPLE_PINHOLE",
    "PINHOLE",
    "SIMPLE_RADIAL",
    "RADIAL",
    "OPENCV",
    "OPENCV_FISHEYE",
    "FULL_OPENCV",
    "FOV",
    "SIMPLE_RADIAL_FISHEYE",
    "RADIAL_FISHEYE",
    "THIN_PRISM_FISHEYE",
    "RAD_TAN_THIN_PRISM_FISHEYE",
];

/// What to do about a camera with distortion we do not model.
const UNDISTORT: &str = "undistort the images first (COLMAP's image_undistorter)";

/// The smallest records in the binary files (with the smallest camera, no 2D points, no
/// track, a one-byte name), which bound how many records the rest of a file can hold.
const CAMERA_BYTES: usize = 4 + 4 + 8 + 8 + 3 * 8;
const IMAGE_BYTES: usize = 4 + 7 * 8 + 4 + 2 + 8;
const POINT_BYTES: usize = 8 + 3 * 8 + 3 + 8 + 8;

/// Whether `dir` holds a COLMAP sparse model (in `sparse/0` or `sparse`).
pub fn is_colmap(dir: &Path) -> bool {
    Sparse::find(dir).is_some()
}

/// Reads the COLMAP dataset in `dir`, with the pictures from the folder `images` (`images`
/// when `None`; a downscaled copy such as `images_4` scales the intrinsics to its size),
/// compositing RGBA images on `background`. Views are sorted by image name and every 8th
/// (from the first) is held out for testing, as 3DGS does; the model's 3D points are the
/// dataset's points.
pub fn read_colmap(
    dir: &Path,
    background: Vec3,
    images: Option<&str>,
) -> Result<Dataset, DatasetError> {
    shots(dir, images)?.load(background)
}

/// The posed pictures of the COLMAP dataset in `dir` (as [`read_colmap`] reads it), without
/// their pixels.
pub(super) fn shots(dir: &Path, images: Option<&str>) -> Result<Shots, DatasetError> {
    let sparse = Sparse::find(dir).ok_or_else(|| DatasetError::NotADataset(dir.to_path_buf()))?;
    let cameras = sparse.cameras()?;
    let mut registered = sparse.registered(&cameras)?;
    if registered.is_empty() {
        return Err(DatasetError::Empty(sparse.file("images")));
    }
    // The whole model before any picture: a broken model fails fast.
    let points = sparse.points()?;
    registered.sort_by(|a, b| a.name.cmp(&b.name));
    let folder = dir.join(images.unwrap_or("images"));
    let cameras_file = sparse.name("cameras");
    let shots = (registered.par_iter())
        .map(|image| image.shot(&folder, &cameras_file))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Shots::every_8th_held_out(shots, points))
}

/// The two encodings of a COLMAP model.
#[derive(Clone, Copy)]
enum Format {
    Binary,
    Text,
}

/// Where a sparse model is and in which format.
struct Sparse {
    dir: PathBuf,
    format: Format,
}

/// An image of the model: its name, its camera's id and that camera posed, with its lens.
struct Registered {
    name: String,
    camera_id: i32,
    camera: Camera,
    lens: Option<Lens>,
}

/// An image record before its camera is looked up.
struct Posed {
    name: String,
    camera_id: i32,
    rotation: Mat3,
    translation: Vec3,
}

impl Sparse {
    /// The model in `dir/sparse/0` or else `dir/sparse`, binary if `cameras.bin` is there,
    /// else text.
    fn find(dir: &Path) -> Option<Sparse> {
        ["sparse/0", "sparse"]
            .into_iter()
            .flat_map(|sub| {
                [Format::Binary, Format::Text].map(|format| Sparse {
                    dir: dir.join(sub),
                    format,
                })
            })
            .find(|s| s.file("cameras").is_file())
    }

    /// The model file `stem` (`cameras`, `images`, `points3D`) in this model's format.
    fn file(&self, stem: &str) -> PathBuf {
        self.dir.join(self.name(stem))
    }

    /// The name of the model file `stem`, for errors about another file.
    fn name(&self, stem: &str) -> String {
        let ext = match self.format {
            Format::Binary => "bin",
            Format::Text => "txt",
        };
        format!("{stem}.{ext}")
    }

    /// The cameras by id: intrinsics at their calibrated size, identity pose, and their lenses.
    fn cameras(&self) -> Result<HashMap<i32, Intrinsics>, DatasetError> {
        let path = self.file("cameras");
        let list = match self.format {
            Format::Binary => binary_file(
                &path,
                "camera",
                CAMERA_BYTES,
                |r: &mut Bin| r.i32(),
                binary_camera,
            )?,
            Format::Text => text_file(&path, "camera", data_lines, text_camera)?,
        };
        let mut cameras = HashMap::with_capacity(list.len());
        for (id, camera) in list {
            if cameras.insert(id, camera).is_some() {
                return Err(field(&path, format!("camera {id}"), "appears twice"));
            }
        }
        Ok(cameras)
    }

    /// The images, each with its camera posed; refused when one names a camera not in
    /// `cameras`.
    fn registered(
        &self,
        cameras: &HashMap<i32, Intrinsics>,
    ) -> Result<Vec<Registered>, DatasetError> {
        let path = self.file("images");
        let list = match self.format {
            Format::Binary => binary_file(
                &path,
                "image",
                IMAGE_BYTES,
                |r: &mut Bin| r.i32(),
                binary_image,
            )?,
            Format::Text => text_file(&path, "image", image_lines, text_image)?,
        };
        list.into_iter()
            .map(|(id, posed)| {
                let (intrinsics, lens) = cameras.get(&posed.camera_id).ok_or_else(|| {
                    let (camera, file) = (posed.camera_id, self.name("cameras"));
                    field(
                        &path,
                        format!("image {id}"),
                        format!("refers to camera {camera}, which is not in {file}"),
                    )
                })?;
                Ok(Registered {
                    name: posed.name,
                    camera_id: posed.camera_id,
                    camera: Camera {
                        rotation: posed.rotation,
                        translation: posed.translation,
                        ..*intrinsics
                    },
                    lens: *lens,
                })
            })
            .collect()
    }

    /// The 3D points with their colors (their tracks and errors are not needed).
    fn points(&self) -> Result<Vec<Point>, DatasetError> {
        let path = self.file("points3D");
        let list = match self.format {
            Format::Binary => binary_file(
                &path,
                "point",
                POINT_BYTES,
                |r: &mut Bin| r.u64(),
                binary_point,
            )?,
            Format::Text => text_file(&path, "point", data_lines, text_point)?,
        };
        Ok(list.into_iter().map(|(_, p): (u64, _)| p).collect())
    }
}

impl Registered {
    /// This image's picture in `folder`, its camera fitted to the picture's size (`cameras`
    /// names the cameras file, for errors).
    fn shot(&self, folder: &Path, cameras: &str) -> Result<Shot, DatasetError> {
        let path = folder.join(&self.name);
        let (width, height) = image_size(&path)?;
        let camera = rescaled(&self.camera, width, height).ok_or_else(|| {
            let want = self.camera.size;
            field(
                &path,
                "size",
                format!(
                    "{width}x{height} does not scale camera {}'s {}x{} in {cameras}: the aspect ratio differs",
                    self.camera_id, want.x, want.y
                ),
            )
        })?;
        let shot = Shot::in_folder(folder.to_path_buf(), path.clone(), camera);
        let Some(lens) = self.lens else {
            return Ok(shot);
        };
        let lens_of = format!("camera {}'s lens (in {cameras})", self.camera_id);
        shot.through(lens).map_err(|p| field(&path, lens_of, p))
    }
}

/// How many parameters COLMAP camera `model` has; refused for the models we cannot train on.
fn param_count(model: i32) -> Result<usize, String> {
    match model {
        0 => Ok(3),
        1 | 2 | 8 => Ok(4),
        3 | 9 => Ok(5),
        4 | 5 => Ok(8),
        6 => Ok(12),
        _ => Err(
            match usize::try_from(model).ok().and_then(|m| MODELS.get(m)) {
                Some(name) => {
                    format!("has the unsupported camera model {name} ({model}): {UNDISTORT}")
                }
                None => format!("has the unknown camera model id {model}: {UNDISTORT}"),
            },
        ),
    }
}

/// A camera's intrinsics (at its calibrated size, with an identity pose) and the lens whose
/// distortion is taken out of its pictures, if any.
type Intrinsics = (Camera, Option<Lens>);

/// The intrinsics of a camera of COLMAP `model` (an index into [`MODELS`]) and `params` (in
/// COLMAP's order) at its calibrated size.
fn intrinsics(model: i32, width: u64, height: u64, params: &[f64]) -> Result<Intrinsics, String> {
    let want = param_count(model)?;
    // A supported model.
    let name = MODELS[model as usize];
    if params.len() != want {
        let got = match params.len() {
            1 => "1 parameter".to_string(),
            n => format!("{n} parameters"),
        };
        return Err(format!("has {got}, but {name} ({model}) has {want}"));
    }
    let p = |i: usize| params[i] as f32;
    // The models with one focal length; the others have two.
    let (focal, principal, k) = match model {
        0 | 2 | 3 | 8 | 9 => (Vec2::splat(p(0)), Vec2::new(p(1), p(2)), &params[3..]),
        _ => (Vec2::new(p(0), p(1)), Vec2::new(p(2), p(3)), &params[4..]),
    };
    if !(focal.is_finite() && principal.is_finite() && focal.min_element() > 0.0) {
        return Err(format!(
            "has the focal length {focal} and principal point {principal}: the focal length must be finite and positive, the principal point finite"
        ));
    }
    let at = |i: usize| k.get(i).copied().unwrap_or(0.0);
    let lens = match model {
        // SIMPLE_RADIAL: k; RADIAL: k1 k2; OPENCV: k1 k2 p1 p2; FULL_OPENCV: k1 k2 p1 p2 k3 k4
        // k5 k6.
        2..=4 | 6 => Lens {
            numerator: [at(0), at(1), at(4), 0.0],
            denominator: [at(5), at(6), at(7)],
            tangential: [at(2), at(3)],
        },
        _ => Lens::default(),
    };
    // OPENCV_FISHEYE: k1 k2 k3 k4; SIMPLE_RADIAL_FISHEYE: k; RADIAL_FISHEYE: k1 k2, all the
    // Kannala-Brandt polynomial in the angle.
    let (camera_model, distortion) = match model {
        5 | 8 | 9 => (
            CameraModel::KannalaBrandt,
            DVec4::new(at(0), at(1), at(2), at(3)).as_vec4(),
        ),
        _ => (CameraModel::Pinhole, Vec4::ZERO),
    };
    let camera = Camera {
        focal,
        principal,
        size: size(width, height)?,
        model: camera_model,
        distortion,
        ..Default::default()
    };
    Ok((camera, (!lens.is_identity()).then_some(lens)))
}

/// An image size, refused when zero or too large to be exact in `f32`.
fn size(width: u64, height: u64) -> Result<Vec2, String> {
    let side = 1..=1 << 24;
    if side.contains(&width) && side.contains(&height) {
        Ok(Vec2::new(width as f32, height as f32))
    } else {
        Err(format!(
            "has the size {width}x{height}, not 1 to 16777216 pixels a side"
        ))
    }
}

/// The world-to-camera rotation and translation of COLMAP's `qw qx qy qz` and `tx ty tz`.
fn pose(q: [f64; 4], t: [f64; 3]) -> Result<(Mat3, Vec3), String> {
    let q = DQuat::from_xyzw(q[1], q[2], q[3], q[0]);
    let norm = q.length();
    if norm < 1e-9 {
        return Err("has a zero rotation quaternion".into());
    }
    Ok((
        DMat3::from_quat(q / norm).as_mat3(),
        single(t, "translation")?,
    ))
}

fn point(position: [f64; 3], rgb: [u8; 3]) -> Result<Point, String> {
    Ok(Point {
        position: single(position, "position")?,
        color: Vec3::from_array(rgb.map(|c| c as f32 / 255.0)),
    })
}

/// `v` in `f32`, refused when it overflows.
fn single(v: [f64; 3], what: &str) -> Result<Vec3, String> {
    let v = DVec3::from_array(v).as_vec3();
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("has the {what} {v}, too large for f32"))
    }
}

/// A cursor over a little-endian binary model file; reading past its end is an error.
struct Bin<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Bin<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let chunk = self
            .bytes
            .get(self.at..self.at + N)
            .ok_or_else(|| self.short())?;
        self.at += N;
        let mut out = [0; N];
        out.copy_from_slice(chunk);
        Ok(out)
    }

    fn short(&self) -> String {
        format!("is cut short: the file ends at byte {}", self.bytes.len())
    }

    fn left(&self) -> usize {
        self.bytes.len() - self.at
    }

    fn i32(&mut self) -> Result<i32, String> {
        self.take().map(i32::from_le_bytes)
    }

    fn u64(&mut self) -> Result<u64, String> {
        self.take().map(u64::from_le_bytes)
    }

    fn finite(&mut self) -> Result<f64, String> {
        let x = f64::from_le_bytes(self.take()?);
        if x.is_finite() {
            Ok(x)
        } else {
            Err(format!("holds the non-finite number {x}"))
        }
    }

    fn finites<const N: usize>(&mut self) -> Result<[f64; N], String> {
        let mut out = [0.0; N];
        for x in &mut out {
            *x = self.finite()?;
        }
        Ok(out)
    }

    /// Skips `items` items of `size` bytes each.
    fn skip(&mut self, items: u64, size: usize) -> Result<(), String> {
        let n = usize::try_from(items)
            .ok()
            .and_then(|n| n.checked_mul(size))
            .filter(|n| *n <= self.left())
            .ok_or_else(|| self.short())?;
        self.at += n;
        Ok(())
    }

    /// A count of records of at least `min_size` bytes, refused when the rest of the file
    /// cannot hold that many (so a corrupt count is an error, not an allocation).
    fn count(&mut self, min_size: usize) -> Result<usize, String> {
        let n = self.u64()?;
        let room = self.left() / min_size;
        usize::try_from(n)
            .ok()
            .filter(|n| *n <= room)
            .ok_or_else(|| {
                format!(
                    "is {n}, but the {} bytes left in the file hold at most {room}",
                    self.left()
                )
            })
    }

    /// A NUL-terminated UTF-8 name.
    fn name(&mut self) -> Result<String, String> {
        let rest = &self.bytes[self.at..];
        let len = rest
            .iter()
            .position(|b| *b == 0)
            .ok_or("has a name without its terminating NUL byte")?;
        let name = std::str::from_utf8(&rest[..len]).map_err(|_| "has a name that is not UTF-8")?;
        if name.is_empty() {
            return Err("has an empty name".into());
        }
        self.at += len + 1;
        Ok(name.to_owned())
    }
}

/// The records of a binary model file: a `u64` count, then records of at least `min_size`
/// bytes, each its id (read by `id`) and the rest (read by `body`). Errors name the file and
/// the record.
fn binary_file<I: Display, T>(
    path: &Path,
    element: &str,
    min_size: usize,
    id: impl Fn(&mut Bin) -> Result<I, String>,
    body: impl Fn(&mut Bin) -> Result<T, String>,
) -> Result<Vec<(I, T)>, DatasetError> {
    let bytes = std::fs::read(path).map_err(|error| DatasetError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    let mut r = Bin {
        bytes: &bytes,
        at: 0,
    };
    let count = r
        .count(min_size)
        .map_err(|p| field(path, format!("the {element} count"), p))?;
    let mut records = Vec::with_capacity(count);
    for k in 0..count {
        let id = id(&mut r).map_err(|p| field(path, format!("{element} record {k}"), p))?;
        let item = body(&mut r).map_err(|p| field(path, format!("{element} {id}"), p))?;
        records.push((id, item));
    }
    Ok(records)
}

fn binary_camera(r: &mut Bin) -> Result<Intrinsics, String> {
    let model = r.i32()?;
    let (width, height) = (r.u64()?, r.u64()?);
    let mut params = vec![0.0; param_count(model)?];
    for p in &mut params {
        *p = r.finite()?;
    }
    intrinsics(model, width, height, &params)
}

fn binary_image(r: &mut Bin) -> Result<Posed, String> {
    let q = r.finites::<4>()?;
    let t = r.finites::<3>()?;
    let camera_id = r.i32()?;
    let name = r.name()?;
    // The 2D points (x, y, point3D id): not needed for training.
    let points = r.u64()?;
    r.skip(points, 24)?;
    let (rotation, translation) = pose(q, t)?;
    Ok(Posed {
        name,
        camera_id,
        rotation,
        translation,
    })
}

fn binary_point(r: &mut Bin) -> Result<Point, String> {
    let position = r.finites::<3>()?;
    let rgb = r.take::<3>()?;
    // The reprojection error, then the track (image id, point2D index): not needed.
    r.skip(1, 8)?;
    let track = r.u64()?;
    r.skip(track, 8)?;
    point(position, rgb)
}

/// The whitespace-separated fields of a line of a text model file.
struct Fields<'a>(std::iter::Peekable<std::str::SplitWhitespace<'a>>);

impl Fields<'_> {
    fn at_end(&mut self) -> bool {
        self.0.peek().is_none()
    }

    fn next<T: FromStr>(&mut self, what: &str) -> Result<T, String> {
        let token = self.0.next().ok_or_else(|| format!("has no {what}"))?;
        token
            .parse()
            .map_err(|_| format!("has `{token}` for its {what}"))
    }

    fn finite(&mut self, what: &str) -> Result<f64, String> {
        let x: f64 = self.next(what)?;
        if x.is_finite() {
            Ok(x)
        } else {
            Err(format!("has the non-finite {what} {x}"))
        }
    }

    fn finites<const N: usize>(&mut self, what: &str) -> Result<[f64; N], String> {
        let mut out = [0.0; N];
        for x in &mut out {
            *x = self.finite(what)?;
        }
        Ok(out)
    }
}

/// The lines of a text model file that hold its records, each with its number from 1, or the
/// number of a line that breaks the file's layout and what is wrong with it.
type Records<'a> = Result<Vec<(usize, &'a str)>, (usize, String)>;

/// The records of a text model file, one per line that `records` picks: each its id and the
/// rest (read by `body`). Errors name the file, the record and the line.
fn text_file<I: FromStr + Display, T>(
    path: &Path,
    element: &str,
    records: fn(&str) -> Records<'_>,
    body: impl Fn(&mut Fields) -> Result<T, String>,
) -> Result<Vec<(I, T)>, DatasetError> {
    let text = std::fs::read_to_string(path).map_err(|error| DatasetError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    records(crate::without_bom(&text))
        .map_err(|(n, p)| field(path, format!("line {n}"), p))?
        .into_iter()
        .map(|(n, line)| {
            let mut fields = Fields(line.split_whitespace().peekable());
            let id: I = fields
                .next("id")
                .map_err(|p| field(path, format!("line {n}"), p))?;
            let item = body(&mut fields)
                .map_err(|p| field(path, format!("{element} {id} (line {n})"), p))?;
            Ok((id, item))
        })
        .collect()
}

/// The lines of a text model file that are not blank or `#` comments.
fn data_lines(text: &str) -> Records<'_> {
    Ok(numbered(text).filter(|(_, l)| is_data(l)).collect())
}

/// The first lines of the two each image has in `images.txt`. The second lists its 2D points
/// (may be blank, or missing after the last image) and is checked to be that: a file with one
/// line per image would otherwise lose every other image.
fn image_lines(text: &str) -> Records<'_> {
    let mut lines = numbered(text);
    let mut records = vec![];
    while let Some((n, line)) = lines.next() {
        if is_data(line) {
            records.push((n, line));
            if let Some((m, points)) = lines.next().filter(|(_, l)| !is_points_2d(l)) {
                let points = points.trim();
                return Err((
                    m,
                    format!(
                        "should list the 2D points (x y point3D_id ...) of the image on line {n}, but is `{points}`"
                    ),
                ));
            }
        }
    }
    Ok(records)
}

/// Whether `line` is an image's 2D points in `images.txt`: `x y point3D_id` triples.
fn is_points_2d(line: &str) -> bool {
    let fields: Vec<&str> = line.split_whitespace().collect();
    fields.len().is_multiple_of(3)
        && fields.chunks_exact(3).all(|p| {
            p[0].parse::<f64>().is_ok()
                && p[1].parse::<f64>().is_ok()
                && p[2].parse::<i64>().is_ok()
        })
}

fn numbered(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines().enumerate().map(|(k, l)| (k + 1, l))
}

fn is_data(line: &str) -> bool {
    let line = line.trim();
    !line.is_empty() && !line.starts_with('#')
}

fn text_camera(f: &mut Fields) -> Result<Intrinsics, String> {
    let name: String = f.next("model")?;
    let model = MODELS
        .iter()
        .position(|m| *m == name)
        .map(|m| m as i32)
        .ok_or_else(|| format!("has the unknown camera model {name}: {UNDISTORT}"))?;
    let (width, height) = (f.next("width")?, f.next("height")?);
    let mut params = vec![];
    while !f.at_end() {
        params.push(f.finite("parameter")?);
    }
    intrinsics(model, width, height, &params)
}

fn text_image(f: &mut Fields) -> Result<Posed, String> {
    let q = f.finites::<4>("rotation")?;
    let t = f.finites::<3>("translation")?;
    let camera_id = f.next("camera id")?;
    // A name may hold spaces: the rest of the line.
    let name = f.0.by_ref().collect::<Vec<_>>().join(" ");
    if name.is_empty() {
        return Err("has no name".into());
    }
    let (rotation, translation) = pose(q, t)?;
    Ok(Posed {
        name,
        camera_id,
        rotation,
        translation,
    })
}

fn text_point(f: &mut Fields) -> Result<Point, String> {
    let position = f.finites::<3>("position")?;
    let rgb = [f.next("red")?, f.next("green")?, f.next("blue")?];
    point(position, rgb)
}
