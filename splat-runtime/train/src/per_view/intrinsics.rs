//! A camera's intrinsics as a run refines them, and the cameras a dataset's views share.

use glam::{Vec2, Vec4};
use splat_core::types::Camera;

/// A correction of a camera's intrinsics: its focal lengths scaled, its principal point
/// shifted and (for a model with a lens, the Kannala-Brandt fisheye) its lens coefficients
/// moved. The scale is a log, so its words share one rate at any focal length; the shift is
/// in image widths, so it does at any size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IntrinsicsCorrection {
    /// Logs of the factors on the focal lengths (fx, fy).
    pub log_focal: Vec2,
    /// The principal point's shift, in units of the image's width.
    pub shift: Vec2,
    /// Added to the lens coefficients (k1..k4); unused by models without them.
    pub distortion: Vec4,
}

impl IntrinsicsCorrection {
    pub const WORDS: usize = 8;

    /// The correction in its 8 words: log-focal, shift, lens.
    pub fn from_words(words: &[f32]) -> IntrinsicsCorrection {
        IntrinsicsCorrection {
            log_focal: Vec2::from_slice(&words[..2]),
            shift: Vec2::from_slice(&words[2..4]),
            distortion: Vec4::from_slice(&words[4..8]),
        }
    }

    /// `camera` with its intrinsics corrected.
    pub fn apply(&self, camera: &Camera) -> Camera {
        Camera {
            focal: camera.focal * self.log_focal.exp(),
            principal: camera.principal + self.shift * camera.size.x,
            distortion: match camera.model.has_distortion() {
                true => camera.distortion + self.distortion,
                false => camera.distortion,
            },
            ..*camera
        }
    }

    /// The gradient by the correction's words, given `camera` (before the correction) and the
    /// cotangent `d` of the corrected camera's intrinsics.
    pub fn backward(&self, camera: &Camera, d: &Camera) -> [f32; 8] {
        let corrected = self.apply(camera);
        let by_log_focal = d.focal * corrected.focal;
        let by_shift = d.principal * camera.size.x;
        let by_lens = match camera.model.has_distortion() {
            true => d.distortion,
            false => Vec4::ZERO,
        };
        let mut g = [0.0; 8];
        g[..2].copy_from_slice(&by_log_focal.to_array());
        g[2..4].copy_from_slice(&by_shift.to_array());
        g[4..].copy_from_slice(&by_lens.to_array());
        g
    }
}

/// The cameras that took a run's training views: views whose intrinsics are equal (model,
/// size, focal lengths, principal point, lens coefficients where the model has them) share
/// one, as a COLMAP camera is shared by the pictures taken with it. A run refines each
/// camera's intrinsics from all its views, and a held-out view of the same intrinsics is
/// rendered through them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Cameras {
    /// Each camera's intrinsics as the data gives them, in the order of their first view.
    intrinsics: Vec<Camera>,
    /// Each training view's camera.
    of_view: Vec<usize>,
}

impl Cameras {
    /// The cameras of the training views taken by `train` (each view's camera).
    pub fn of<'a>(train: impl IntoIterator<Item = &'a Camera>) -> Cameras {
        let mut cameras = Cameras::default();
        for camera in train {
            let k = match cameras.find(camera) {
                Some(k) => k,
                None => {
                    cameras.intrinsics.push(*camera);
                    cameras.intrinsics.len() - 1
                }
            };
            cameras.of_view.push(k);
        }
        cameras
    }

    /// How many there are.
    pub fn len(&self) -> usize {
        self.intrinsics.len()
    }

    pub fn is_empty(&self) -> bool {
        self.intrinsics.is_empty()
    }

    /// Training view `k`'s camera.
    pub fn of_view(&self, k: usize) -> usize {
        self.of_view[k]
    }

    /// The camera with `camera`'s intrinsics, if one took a training view.
    pub fn find(&self, camera: &Camera) -> Option<usize> {
        self.intrinsics
            .iter()
            .position(|c| same_intrinsics(c, camera))
    }

    /// Each camera's intrinsics as the data gives them.
    pub fn intrinsics(&self) -> &[Camera] {
        &self.intrinsics
    }
}

/// Whether `a` and `b` have the same intrinsics, bit for bit.
fn same_intrinsics(a: &Camera, b: &Camera) -> bool {
    let lens = !a.model.has_distortion() || a.distortion == b.distortion;
    a.model == b.model
        && a.size == b.size
        && a.focal == b.focal
        && a.principal == b.principal
        && lens
}

#[cfg(test)]
mod tests {
    use super::*;
    use splat_core::types::CameraModel;

    /// The backward pass against f64 finite differences of `<a, f'> + <b, c'> + <e, k'>` on
    /// both kinds of models, at zero and away from it.
    #[test]
    fn intrinsics_gradients_match_finite_differences() {
        let (a, b, e) = ([0.7f64, -1.3], [0.4f64, 0.9], [0.3f64, -0.2, 1.1, -0.6]);
        for model in [CameraModel::Pinhole, CameraModel::KannalaBrandt] {
            let camera = Camera {
                focal: Vec2::new(30.0, 34.0),
                principal: Vec2::new(19.0, 21.5),
                size: Vec2::new(40.0, 44.0),
                distortion: Vec4::new(0.05, -0.01, 0.002, 0.0),
                model,
                ..Default::default()
            };
            let d = Camera {
                focal: Vec2::new(a[0] as f32, a[1] as f32),
                principal: Vec2::new(b[0] as f32, b[1] as f32),
                distortion: Vec4::from_array(e.map(|x| x as f32)),
                ..Camera::ZERO
            };
            let lens = model.has_distortion() as u8 as f64;
            let loss = |w: &[f64; 8]| {
                let f = [
                    camera.focal.x as f64 * w[0].exp(),
                    camera.focal.y as f64 * w[1].exp(),
                ];
                let c = [
                    camera.principal.x as f64 + w[2] * 40.0,
                    camera.principal.y as f64 + w[3] * 40.0,
                ];
                let k: f64 = (0..4).map(|i| e[i] * w[4 + i]).sum();
                a[0] * f[0] + a[1] * f[1] + b[0] * c[0] + b[1] * c[1] + lens * k
            };
            for at in [[0.0; 8], [0.1, -0.05, 0.01, -0.02, 0.01, 0.0, -0.01, 0.02]] {
                let words = at.map(|x| x as f32);
                let got = IntrinsicsCorrection::from_words(&words).backward(&camera, &d);
                let what = format!("{model:?} at {at:?}");
                super::super::tests::assert_finite_differences(&what, at, got, loss);
            }
        }
    }

    /// Views of equal intrinsics share a camera whatever their poses; a held-out view finds
    /// it, and one of other intrinsics finds none.
    #[test]
    fn views_of_equal_intrinsics_share_a_camera() {
        let camera = |focal: f32, x: f32| Camera {
            focal: Vec2::splat(focal),
            principal: Vec2::splat(20.0),
            size: Vec2::splat(40.0),
            translation: glam::Vec3::new(x, 0.0, 3.0),
            ..Default::default()
        };
        let views = [camera(30.0, 0.0), camera(32.0, 1.0), camera(30.0, 2.0)];
        let cameras = Cameras::of(&views);
        assert_eq!(cameras.len(), 2);
        assert_eq!(
            (0..3).map(|k| cameras.of_view(k)).collect::<Vec<_>>(),
            [0, 1, 0]
        );
        assert_eq!(cameras.find(&camera(32.0, 5.0)), Some(1));
        assert_eq!(cameras.find(&camera(31.0, 0.0)), None);
    }
}
