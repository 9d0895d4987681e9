// LinPrim (von Lützow and Nießner 2025; as in XPR, Rhyner et al. 2026, §A.1.3): octahedra
// of homogeneous density, linearized into the (x_px, y_px, distance) frame, where each is the intersection of four
// slab pairs; evaluated by the chord of the pixel's ray through the slabs (Beer-Lambert
// opacity), and culled per tile by the chord upper bound of XPR eq. 2. The projection is
// the pinhole Jacobian, so the method is pinhole-only.

#[splat_macros::splat_method(name = "linprim")]
pub mod linprim {
    use splat_runtime::prelude::*;

    pub const NEAR: f32 = 0.01;
    pub const ALPHA_MIN: f32 = 1.0 / 255.0;
    /// Below this |n_z| a slab is parallel to the rays: it bounds no chord.
    pub const EPS: f32 = 1e-10;
    /// Stands for an unbounded slab end.
    pub const FAR: f32 = 1e10;

    pub struct Params {
        pub mean: Vec3,
        /// Natural log of the three half-extents (centre to vertex).
        pub log_scale: Vec3,
        /// Rotation quaternion (w, x, y, z), normalized here.
        pub rotation: Vec4,
        pub opacity_logit: f32,
        pub sh: [Vec3; 16],
    }

    pub struct Slabs {
        pub center: Vec2,
        /// Rows c0, c1, c2 of A^-1: the octahedron is |c0.v| + |c1.v| + |c2.v| <= 1 for
        /// v = (x_px - centre, y_px - centre, distance - its centre's).
        pub rows: Mat3,
        /// Density: -ln(1 - 0.99 o) / (2 min half-extent).
        pub sigma: f32,
    }

    pub struct Shade {
        pub slabs: Slabs,
        pub color: Vec3,
    }

    /// The four slab normals c0 ± c1 ± c2.
    fn normals(rows: Mat3) -> [Vec3; 4] {
        let (c0, c1, c2) = (rows.row(0), rows.row(1), rows.row(2));
        [c0 + c1 + c2, c0 + c1 - c2, c0 - c1 + c2, c0 - c1 - c2]
    }

    /// Mid-depth m of a slab |n.(d, tau)| <= 1 at pixel offset d (0 for a parallel slab).
    fn mid(n: Vec3, d: Vec2) -> f32 {
        select(n.z.abs() >= EPS, -(n.x * d.x + n.y * d.y) / n.z, 0.0)
    }

    /// Half-width h = 1 / |n_z| of a slab in depth (FAR for a parallel slab).
    fn half(n: Vec3) -> f32 {
        select(n.z.abs() >= EPS, 1.0 / n.z.abs(), FAR)
    }

    pub fn project(p: &Params, cam: &Camera) -> Projected<Slabs, Shade> {
        let t = cam.rotation * p.mean + cam.translation;
        let (f, z, dist) = (cam.focal, t.z.max(NEAR), t.length());
        let center = Vec2::new(f.x * t.x / z, f.y * t.y / z) + cam.principal;
        // Projective Jacobian with a third row for the distance from the camera.
        let j = Mat3::from_cols(
            Vec3::new(f.x / z, 0.0, t.x / dist),
            Vec3::new(0.0, f.y / z, t.y / dist),
            Vec3::new(-f.x * t.x / (z * z), -f.y * t.y / (z * z), t.z / dist),
        );
        let scale = p.log_scale.exp();
        let a = j * cam.rotation * blocks::rotation_matrix(p.rotation) * Mat3::from_diagonal(scale);
        let opacity = sigmoid(p.opacity_logit).min(0.999);
        let sigma = -(1.0 - 0.99 * opacity).ln() / (2.0 * scale.min_element());
        // The vertices are the centre ± the columns of A.
        let (ax, ay, az) = (a.x_axis.abs(), a.y_axis.abs(), a.z_axis.abs());
        let extent = Vec2::new(ax.x.max(ay.x).max(az.x), ax.y.max(ay.y).max(az.y));
        let slabs = Slabs {
            center,
            rows: a.inverse(),
            sigma,
        };
        // Frustum cull with the 3DGS guard band (1.3x the half field of view): far off axis
        // the linearization describes nothing the camera sees.
        let tangent = Vec2::new(t.x, t.y) / z;
        let guard = ((cam.size - cam.principal).max(cam.principal) / f) * 1.3;
        Projected {
            visible: t.z > NEAR
                && tangent.x.abs() <= guard.x
                && tangent.y.abs() <= guard.y
                && a.determinant().abs() > 1e-30,
            depth: dist,
            bbox_min: center - extent,
            bbox_max: center + extent,
            cull: slabs,
            shade: Shade {
                slabs,
                color: (spherical_harmonics(p.sh, p.mean - cam.center()) + 0.5).max(Vec3::ZERO),
            },
        }
    }

    /// Seed 000 eq. 2: over the tile, no chord is longer than the smallest over slab pairs
    /// (i, j) of h_i + h_j + max over the tile's corners of m_i - m_j (affine, so the corners
    /// bound it). Keep the tile when that chord could reach ALPHA_MIN.
    pub fn tile_cull(tile: &Tile, s: &Slabs) -> bool {
        let n = normals(s.rows);
        let corners = [
            tile.min,
            Vec2::new(tile.min.x, tile.max.y),
            Vec2::new(tile.max.x, tile.min.y),
            tile.max,
        ];
        let mut chord = FAR;
        for i in 0..4 {
            for j in 0..4 {
                let mut gap = -FAR;
                for k in 0..4 {
                    let d = corners[k] - s.center;
                    gap = gap.max(mid(n[i], d) - mid(n[j], d));
                }
                chord = chord.min(half(n[i]) + half(n[j]) + gap);
            }
        }
        s.sigma * chord.max(0.0) >= -(1.0 - ALPHA_MIN).ln()
    }

    /// The ray through the pixel enters the octahedron at the last slab entry and leaves at
    /// the first slab exit; alpha = 1 - exp(-sigma * chord), at most 0.99.
    pub fn evaluate(px: Vec2, s: &Shade) -> Contribution<Vec3> {
        let n = normals(s.slabs.rows);
        let d = px - s.slabs.center;
        let mut enter = -FAR;
        let mut exit = FAR;
        for i in 0..4 {
            // A slab parallel to the ray holds all of it or none of it.
            let outside = n[i].z.abs() < EPS && (n[i].x * d.x + n[i].y * d.y).abs() > 1.0;
            enter = enter.max(select(outside, FAR, mid(n[i], d) - half(n[i])));
            exit = exit.min(mid(n[i], d) + half(n[i]));
        }
        let chord = (exit - enter).max(0.0);
        let alpha = (1.0 - (-s.slabs.sigma * chord).exp()).min(0.99);
        Contribution {
            alpha,
            color: s.color,
            valid: alpha >= ALPHA_MIN,
        }
    }
}

/// A stored Gaussian becomes the octahedron with vertices at two standard deviations.
impl crate::FromStored for linprim::Params {
    fn from_stored(g: &splat_runtime::io::ply::StoredGaussian) -> Self {
        linprim::Params {
            mean: g.mean,
            log_scale: g.log_scale + std::f32::consts::LN_2,
            rotation: g.rotation,
            opacity_logit: g.opacity_logit,
            sh: g.sh,
        }
    }
}

/// And back: the Gaussian whose two standard deviations reach the vertices.
impl crate::ToStored for linprim::Params {
    fn to_stored(&self) -> splat_runtime::io::ply::StoredGaussian {
        splat_runtime::io::ply::StoredGaussian {
            mean: self.mean,
            log_scale: self.log_scale - std::f32::consts::LN_2,
            rotation: self.rotation,
            opacity_logit: self.opacity_logit,
            sh: self.sh,
        }
    }
}
