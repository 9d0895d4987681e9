//! Stages 1-2: `project` over every primitive (parallel over primitives), then keep the
//! visible ones whose box covers at least one pixel.

use super::grid::{TileGrid, TileRect};
use crate::method::SplatMethod;
use crate::types::{Camera, Projected};
use rayon::prelude::*;

pub struct Preprocessed<M: SplatMethod> {
    /// `project`'s output for every primitive.
    pub projected: Vec<Projected<M::Cull, M::Shade>>,
    /// Indices of the primitives that reach the rasterizer, with their tile rectangles.
    pub visible: Vec<(u32, TileRect)>,
}

pub fn preprocess<M: SplatMethod>(
    params: &[M::Params],
    camera: &Camera,
    grid: &TileGrid,
) -> Preprocessed<M> {
    let projected: Vec<_> = crate::with_camera_model!(camera.model, MODEL => params
        .par_iter()
        .map(|p| M::project_as::<MODEL>(p, camera))
        .collect());
    filter::<M>(projected, grid)
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
    Preprocessed { projected, visible }
}
