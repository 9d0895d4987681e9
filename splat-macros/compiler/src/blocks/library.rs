// splat's building blocks: functions in the accepted subset that every `#[splat_method]`
// module may call as `blocks::name(..)`, compiled and differentiated like the module's own
// code (inlined into each kernel, so a block costs what its lines cost and a result a kernel
// never reads costs nothing). This file is not a module of the compiler: `blocks/mod.rs`
// reads its text; the compiler's tests type-check it and hold 3DGS, GES and the surfels
// example, which call it, to their checks. Written in the conventions of 3DGS / gsplat's
// "classic" mode: OpenCV camera, pixel centres at +0.5, quaternions stored (w, x, y, z).

/// The rotation matrix of the quaternion `q`, stored (w, x, y, z) as 3DGS and its PLY files
/// store it, normalized here (so any nonzero `q` is a rotation).
pub fn rotation_matrix(q: Vec4) -> Mat3 {
    Mat3::from_quat(Quat::from_xyzw(q.y, q.z, q.w, q.x).normalize())
}

/// A 3D Gaussian's footprint on the image (EWA splatting, [`gaussian_footprint`]).
pub struct Footprint {
    /// Where the mean lands on the image, in pixels.
    pub center: Vec2,
    /// The mean's camera-space z.
    pub depth: f32,
    /// The 2D covariance after dilation, (xx, xy, yy) in px^2.
    pub cov: Vec3,
    /// Its inverse (xx, xy, yy): a pixel at offset `d` from `center` is at squared
    /// Mahalanobis distance `conic_distance2(d, conic)`.
    pub conic: Vec3,
    /// sqrt(det(cov before dilation) / det(cov)): how much the dilation grew the footprint's
    /// area, the opacity scale of anti-aliasing (Mip-Splatting's 2D filter, gsplat's
    /// `antialiased` mode). A kernel that never reads it computes none of it.
    pub compensation: f32,
    /// The mean is beyond `near`, the camera model can project it and the covariance is
    /// positive definite.
    pub visible: bool,
}

/// The footprint of the 3D Gaussian at `mean` (world space) with axis scales
/// `exp(log_scale)` turned by `rotation` ((w, x, y, z), normalized here): its covariance
/// projected through the camera's Jacobian at the mean (derived for every camera model; on the
/// pinhole at the tangent clamp of 3DGS / gsplat, so a Gaussian far off the image is not
/// stretched without bound), plus `dilation` px^2 on the diagonal (3DGS: 0.3).
pub fn gaussian_footprint(
    mean: Vec3,
    log_scale: Vec3,
    rotation: Vec4,
    cam: &Camera,
    near: f32,
    dilation: f32,
) -> Footprint {
    let t = cam.rotation * mean + cam.translation;
    let z = t.z.max(near);
    let (f, c, size) = (cam.focal, cam.principal, cam.size);
    let at_mean = Vec3::new(t.x, t.y, z);
    let lim_pos = (size - c) / f + size * 0.15 / f;
    let lim_neg = c / f + size * 0.15 / f;
    let tx = (t.x / z).clamp(-lim_neg.x, lim_pos.x) * z;
    let ty = (t.y / z).clamp(-lim_neg.y, lim_pos.y) * z;
    let at = select(cam.is_pinhole(), Vec3::new(tx, ty, z), at_mean);
    let (_, d) = jacobian(|q| cam.project_point(q), at);
    let j = Mat3::from_cols(
        Vec3::new(d[0].x, d[1].x, 0.0),
        Vec3::new(d[0].y, d[1].y, 0.0),
        Vec3::new(d[0].z, d[1].z, 0.0),
    );
    let m = cam.rotation * rotation_matrix(rotation) * Mat3::from_diagonal(log_scale.exp());
    let cov = j * (m * m.transpose()) * j.transpose();
    let (a0, b, d0) = (cov.x_axis.x, cov.y_axis.x, cov.y_axis.y);
    let (a, d) = (a0 + dilation, d0 + dilation);
    let det = a * d - b * b;
    Footprint {
        center: cam.project_point(at_mean),
        depth: t.z,
        cov: Vec3::new(a, b, d),
        conic: Vec3::new(d, -b, a) / det,
        compensation: ((a0 * d0 - b * b) / det).max(0.0).sqrt(),
        visible: t.z > near && cam.can_project(t) && det > 0.0,
    }
}

/// `d^T conic d`: the squared Mahalanobis distance of the offset `d` under the 2D covariance
/// whose inverse is `conic` (xx, xy, yy). A Gaussian's alpha is `opacity * exp(-0.5 * q)`.
pub fn conic_distance2(d: Vec2, conic: Vec3) -> f32 {
    conic.x * d.x * d.x + 2.0 * conic.y * d.x * d.y + conic.z * d.y * d.y
}

/// The half-width, in whole pixels, of a square around a footprint's centre that holds every
/// offset within squared distance `q_max` of it (`conic_distance2 <= q_max`) under the 2D
/// covariance `cov` (xx, xy, yy): sqrt(q_max) times the major axis' sigma. With `q_max` where
/// a falloff drops below the blend's threshold (3DGS: 2 ln(opacity / ALPHA_MIN)) the box culls
/// nothing the threshold would keep.
pub fn footprint_radius(cov: Vec3, q_max: f32) -> f32 {
    let det = cov.x * cov.z - cov.y * cov.y;
    let mid = 0.5 * (cov.x + cov.z);
    let lambda = mid + (mid * mid - det).max(0.1).sqrt();
    (q_max * lambda).sqrt().ceil()
}

/// Whether a footprint centred at `center` with inverse covariance `conic` comes within
/// squared distance `q_max` of a pixel centre of `tile` (StopThePop's exact tile cull, XPR
/// Listing 1): the nearest point of the tile to the centre under the conic's metric is the
/// centre itself or on an edge facing it, where the 1D minimum along the edge is clamped to
/// the edge.
pub fn conic_tile_cull(tile: &Tile, center: Vec2, conic: Vec3, q_max: f32) -> bool {
    let (mu, k) = (center, conic);
    let dx = mu.x - mu.x.clamp(tile.min.x, tile.max.x);
    let dy1 = mu.y - (mu.y + k.y * dx / k.z).clamp(tile.min.y, tile.max.y);
    let dy = mu.y - mu.y.clamp(tile.min.y, tile.max.y);
    let dx2 = mu.x - (mu.x + k.y * dy / k.x).clamp(tile.min.x, tile.max.x);
    let p1 = k.x * dx * dx + 2.0 * k.y * dx * dy1 + k.z * dy1 * dy1;
    let p2 = k.x * dx2 * dx2 + 2.0 * k.y * dx2 * dy + k.z * dy * dy;
    p1.min(p2) <= q_max
}
