//! Stages 1-2: `project` over every primitive (parallel over primitives), then keep the
//! visible ones whose box covers at least one pixel; the shade data is packed where the frame
//! stores it in a reduced format.

use super::grid::{TileGrid, TileRect};
use super::precision::{PackedShade, Precision};
use crate::method::SplatMethod;
use crate::types::{Camera, Projected};
use rayon::prelude::*;

pub struct Preprocessed<M: SplatMethod> {
    /// `project`'s output for every primitive.
    pub projected: Vec<Projected<M::Cull, M::Shade>>,
    /// Indices of the primitives that reach the rasterizer, with their tile rectangles.
    pub visible: Vec<(u32, TileRect)>,
    /// The shade data in the frame's reduced format, which the blend reads instead of
    /// `projected`'s (none at f32).
    pub packed: Option<PackedShade>,
}

impl<M: SplatMethod> Preprocessed<M> {
    /// The shade data of the primitives `list` names, as the blend reads them: decoded from
    /// the packed store where there is one (none: `projected`'s own).
    pub fn decoded(&self, list: &[u32]) -> Option<Vec<M::Shade>> {
        self.packed.as_ref().map(|p| p.decode(list))
    }
}

pub fn preprocess<M: SplatMethod>(
    params: &[M::Params],
    camera: &Camera,
    grid: &TileGrid,
    shade_precision: Precision,
) -> Preprocessed<M> {
    let projected: Vec<_> = crate::with_camera_model!(camera.model, MODEL => params
        .par_iter()
        .map(|p| M::project_as::<MODEL>(p, camera))
        .collect());
    let mut pre = filter::<M>(projected, grid);
    if shade_precision != Precision::F32 {
        pre.packed = Some(PackedShade::new::<M>(shade_precision, &pre.projected));
    }
    pre
}

/// Keeps the primitives `project` marked visible, with a finite depth and at least one pixel.
pub fn filter<M: SplatMethod>(
    projected: Vec<Projected<M::Cull, M::Shade>>,
    grid: &TileGrid,
) -> Preprocessed<M> {
    let visible = projected
        .par_iter()
        .enumerate()
        .filter_map(|(i, p)| {
            if !p.visible || !p.depth.is_finite() {
                return None;
            }
            grid.rect(p.bbox_min, p.bbox_max).map(|r| (i as u32, r))
        })
        .collect();
    Preprocessed {
        projected,
        visible,
        packed: None,
    }
}
