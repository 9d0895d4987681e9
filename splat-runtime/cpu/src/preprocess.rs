//! Stages 1-2: `project` over every primitive (parallel over primitives), then keep the
//! visible ones whose box covers at least one pixel; the shade data is packed where the frame
//! stores it in a reduced format.

use rayon::prelude::*;
use splat_core::grid::{TileGrid, TileRect};
use splat_core::method::SplatMethod;
use splat_core::precision::{PackedShade, Precision};
use splat_core::types::{Camera, Projected};

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
    /// The shade data of a tile's `list`, as the blend reads it.
    pub fn tile_shades<'a>(&'a self, list: &'a [u32]) -> TileShades<'a, M> {
        TileShades {
            pre: self,
            list,
            decoded: vec![],
        }
    }
}

/// The shade data of one tile's list: `project`'s own, or, where the frame packs it, decoded
/// from the packed store the first time the walk reaches it, a block of entries at a time
/// (the walks stop early, so the tail of a long list is never decoded).
pub struct TileShades<'a, M: SplatMethod> {
    pre: &'a Preprocessed<M>,
    list: &'a [u32],
    decoded: Vec<M::Shade>,
}

impl<M: SplatMethod> TileShades<'_, M> {
    /// Entries decoded at a time.
    const BLOCK: usize = 32;

    /// The shade data of entry `k` of the list.
    #[inline(always)]
    pub fn get(&mut self, k: usize) -> &M::Shade {
        let Some(packed) = &self.pre.packed else {
            return &self.pre.projected[self.list[k] as usize].shade;
        };
        while self.decoded.len() <= k {
            let from = self.decoded.len();
            let to = (from + Self::BLOCK).max(k + 1).min(self.list.len());
            let block = self.list[from..to]
                .iter()
                .map(|&i| packed.get::<M::Shade>(i as usize));
            self.decoded.extend(block);
        }
        &self.decoded[k]
    }
}

pub fn preprocess<M: SplatMethod>(
    params: &[M::Params],
    camera: &Camera,
    grid: &TileGrid,
    shade_precision: Precision,
) -> Preprocessed<M> {
    let projected: Vec<_> = splat_core::with_camera_model!(camera.model, MODEL => params
        .par_iter()
        .map(|p| M::project_as::<MODEL>(p, camera))
        .collect());
    from_records(projected, grid, shade_precision)
}

/// `project`'s `records` (every primitive's, or the visible ones of slices rendered
/// together), filtered and packed as [`preprocess`] does.
pub fn from_records<M: SplatMethod>(
    records: Vec<Projected<M::Cull, M::Shade>>,
    grid: &TileGrid,
    shade_precision: Precision,
) -> Preprocessed<M> {
    let mut pre = filter::<M>(records, grid);
    if shade_precision != Precision::F32 {
        let packed = PackedShade::new::<M>(shade_precision, &pre.projected, &pre.visible);
        pre.packed = Some(packed);
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
