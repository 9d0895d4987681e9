"""Independent references for 3DGUT, 3DGEER and LinPrim: images and gradients written here in
float64 from the papers' math (numpy and torch's autograd, nothing from our compiler or our
method sources), committed as fixtures that `methods/tests/independent_reference.rs` compares
the CPU and GPU pipelines against, as it does gsplat's for 3DGS (`../gsplat/make_fixtures.py`,
whose fixture format, blend and clear-pixel rule this follows).

What is written from which paper (`shared/papers/`: 000 = XPR, 003 = 3DGEER):
- 3DGUT (000 §A.1.2): the unscented transform of the Gaussian's seven sigma points (alpha 1,
  beta 2, kappa 0: mean weights 0 and 1/6, covariance weights 2 and 1/6) through the camera
  model's projection gives the 2D covariance, whose Mip-Splatting filter (0.3 px^2 on the
  diagonal) scales the opacity by sqrt(det / det filtered); the pixel's alpha is that opacity
  times the Gaussian's largest response on the pixel's ray, eq. 1: tau_max =
  (mu - o)^T Sigma^-1 d / d^T Sigma^-1 d, written here with Sigma^-1 = R S^-2 R^T in world
  space (not the canonical frame).
- 3DGEER (003 App. B, eq. B.5-B.9 and Theorem 1): the canonical density
  exp(-|u|^2 / 2) / sqrt(2 pi) integrated along the ray from the camera: opacity *
  exp(-D^2 / 2) * Phi(s*), with D^2 the least Mahalanobis distance of the ray's points
  (evaluated at the closest point, not through the cross product) and s* that point's signed
  canonical distance along the ray; Phi from erfc in float64.
- LinPrim (000 §A.1.3): the octahedron ||A^-1 (p - mu_2D, tau)||_1 <= 1 in the linearized
  (x_px, y_px, distance) frame, A = J R_w2c R diag(s), J the pinhole Jacobian with a third row
  t / |t|; the chord is the tau interval where that convex piecewise-linear norm is at most 1,
  found here from its breakpoints (not from the four slab pairs); alpha by Beer-Lambert with
  the density -ln(1 - 0.99 o) / (2 min s), o = min(sigmoid, 0.999).
- The camera models from their definitions: pinhole; equiangular (BEAP: pixel = f (atan2(x, z),
  atan2(y, z)) + c, so the ray through a pixel is (tan, tan, 1)); Kannala-Brandt (OpenCV
  fisheye, r(theta) = theta (1 + k1 theta^2 + ... + k4 theta^8), inverted by Newton's method
  to convergence and differentiated implicitly by one last step).
Before writing anything the script checks the closed forms against brute force (a dense
search for 3DGUT's maximum, Simpson quadrature of 3DGEER's integral, a dense sampling of
LinPrim's L1 condition) and each camera's ray against its projection.

The fixtures: 3DGUT (`gut`, SH degree 3) on a pinhole, the equiangular model and a distorted
fisheye; 3DGEER (`geer`) on the same three; LinPrim (`linprim`) on a pinhole; 48 to 60
primitives each on 48 x 32 or 40 x 40 pixels, turned and moved cameras with fx != fy and the
principal point off centre. Besides Gaussians 2 to 6 units away, each 3DGUT and 3DGEER scene has
faint ones a sigma or two from the camera, so that 3DGEER's Phi(s*) is well below 1 (and s*
negative) on many pixels, and the fisheye's 3DGUT scene one beside the camera, whose closest
point on most rays lies behind it (tau_max clamped).

Our conventions (splat's DESIGN.md §6, `methods/src/{unscented,exact,linear}.rs`,
`splat-runtime/core/src/cameras.rs`): OpenCV camera, world-to-camera p -> R p + t with R's nine
entries differentiated as they are (camera centre -R^T t, world ray R^T d); pixel centres at
+0.5; quaternion (w, x, y, z) normalized; scale exp(log scale); color = SH(mean - centre) +
0.5 clamped at 0 (the INRIA basis); rays start at the camera (3DGUT's tau_max clamped at 0);
alpha clamped at 0.99 and pairs below 1/255 skipped; the sort key and what the expected depth
averages is the mean's distance from the camera; a primitive is dropped when its mean
(3DGEER) or any sigma point (3DGUT) is within 0.01 of the camera or where the model cannot
project it (behind the image plane; for the fisheye past 3 rad or the polynomial's fold), when
its opacity is below 1/255 (3DGUT: after the filter), and LinPrim's when its camera-space z is
below 0.01 or its centre off the 3DGS guard band, 1.3x the half field of view. A fixture's
`params` are the stored Gaussian's words, as our loaders read them: LinPrim's half-extents are
twice its scales (exp(log scale + ln 2)).

A pixel is *clear* as for gsplat's fixtures: no pair's alpha within 1e-4 (relative) of 1/255
or of 0.99, no T-stop within 1e-3 (relative) of 1e-4; the loss weights are zero off the clear
pixels and the image comparison skips them.

Run from the repository root (torch from PyPI runs on the CPU; half a minute):

    pip install torch==2.9.1 && python3 methods/tests/first_principles/make_fixtures.py
"""

import json
import math
import pathlib

import numpy as np
import torch

torch.set_default_dtype(torch.float64)

ALPHA_MIN = 1.0 / 255.0
ALPHA_MAX = 0.99
T_MIN = 1e-4
NEAR = 0.01
ALPHA_MARGIN = 1e-4
T_MARGIN = 1e-3
# Mip-Splatting's filter, px^2 on the 2D covariance's diagonal (3DGUT's opacity).
FILTER = 0.3

OUT = pathlib.Path(__file__).parent

# Real SH, the basis of 3DGS (DESIGN.md §6): band 1 to 3 constants.
C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = [
    1.0925484305920792,
    -1.0925484305920792,
    0.31539156525252005,
    -1.0925484305920792,
    0.5462742152960396,
]
C3 = [
    -0.5900435899266435,
    2.890611442640554,
    -0.4570457994644658,
    0.3731763325901154,
    -0.4570457994644658,
    1.445305721320277,
    -0.5900435899266435,
]


def f32(a):
    """Values an f32 renderer can take as they are."""
    return np.asarray(a, dtype=np.float32).astype(np.float64)


# --- Camera models, from their definitions ------------------------------------------------


def kb_radius(theta, k):
    """Kannala-Brandt's r(theta) in focal units."""
    t2 = theta * theta
    return theta * (1 + k[0] * t2 + k[1] * t2**2 + k[2] * t2**3 + k[3] * t2**4)


def kb_slope(theta, k):
    t2 = theta * theta
    return 1 + 3 * k[0] * t2 + 5 * k[1] * t2**2 + 7 * k[2] * t2**3 + 9 * k[3] * t2**4


def project(cam, p):
    """Camera-space points (..., 3) to pixels (..., 2) under the camera's model."""
    f, c = cam["focal"], cam["principal"]
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    if cam["model"] == "pinhole":
        uv = torch.stack([x / z, y / z], -1)
    elif cam["model"] == "equiangular":
        uv = torch.stack([torch.atan2(x, z), torch.atan2(y, z)], -1)
    else:
        rho = torch.sqrt(x * x + y * y)
        theta = torch.atan2(rho, z)
        r = kb_radius(theta, cam["distortion"])
        uv = torch.stack([x, y], -1) * (r / rho)[..., None]
    return f * uv + c


def projectable(cam, p):
    """Whether the model maps camera-space point `p` (numpy) to a meaningful pixel: in front of
    the image plane; for the fisheye, below 3 rad (our can_project) where r(theta) rises."""
    if cam["model"] != "kannala_brandt":
        return p[2] > 0
    theta = math.atan2(math.hypot(p[0], p[1]), p[2])
    k = cam["distortion"].detach().numpy()
    grid = np.linspace(0, theta, 200)
    return theta < 3.0 and bool(np.all(kb_slope(grid, k) > 0))


def ray(cam, pixels):
    """Camera-space unit directions (P, 3) through pixel positions (P, 2)."""
    f, c = cam["focal"], cam["principal"]
    m = (pixels - c) / f
    if cam["model"] == "pinhole":
        d = torch.cat([m, torch.ones(m.shape[0], 1)], -1)
    elif cam["model"] == "equiangular":
        # atan2(x, z) = m.x and atan2(y, z) = m.y, with z > 0.
        d = torch.cat([torch.tan(m), torch.ones(m.shape[0], 1)], -1)
    else:
        k = cam["distortion"]
        r = torch.linalg.norm(m, dim=-1)
        # r(theta) = r by Newton's method to convergence (no gradient), then one step with the
        # gradient: dtheta = (dr - dr(theta)/dk dk) / r'(theta), the implicit derivative.
        with torch.no_grad():
            theta = r.clone()
            for _ in range(50):
                theta = theta - (kb_radius(theta, k) - r) / kb_slope(theta, k)
        theta = theta - (kb_radius(theta, k) - r) / kb_slope(theta, k)
        d = torch.cat([m / r[:, None] * torch.sin(theta)[:, None], torch.cos(theta)[:, None]], -1)
    return d / torch.linalg.norm(d, dim=-1, keepdim=True)


# --- The primitive ------------------------------------------------------------------------


def quaternion_matrix(q):
    """The rotation of quaternion (w, x, y, z), normalized."""
    w, x, y, z = q / torch.linalg.norm(q)
    return torch.stack(
        [
            torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)]),
            torch.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)]),
            torch.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]),
        ]
    )


def sh_color(sh, direction):
    """SH (16 x 3) evaluated along `direction` (normalized here), + 0.5, clamped at 0."""
    x, y, z = direction / torch.linalg.norm(direction)
    xx, yy, zz = x * x, y * y, z * z
    basis = torch.stack(
        [
            torch.tensor(C0),
            -C1 * y,
            C1 * z,
            -C1 * x,
            C2[0] * x * y,
            C2[1] * y * z,
            C2[2] * (2 * zz - xx - yy),
            C2[3] * x * z,
            C2[4] * (xx - yy),
            C3[0] * y * (3 * xx - yy),
            C3[1] * x * y * z,
            C3[2] * y * (4 * zz - xx - yy),
            C3[3] * z * (2 * zz - 3 * xx - 3 * yy),
            C3[4] * x * (4 * zz - xx - yy),
            C3[5] * z * (xx - yy),
            C3[6] * x * (xx - 3 * yy),
        ]
    )
    return torch.clamp_min(basis @ sh + 0.5, 0.0)


def unpack(w):
    """Our parameter words: mean, log scale, quaternion (w, x, y, z), opacity logit, SH."""
    return w[0:3], w[3:6], w[6:10], w[10], w[11:].reshape(16, 3)


# --- The three methods: per primitive, its sort depth, whether it is kept, its color and its
# raw alpha (before the 0.99 clamp) at every pixel ------------------------------------------


def closest_on_ray(origin, dirs, mu, precision):
    """For rays origin + tau d (d: P x 3): tau of the least Mahalanobis distance to the
    Gaussian (mu, precision = Sigma^-1), and d^T Sigma^-1 d."""
    pd = dirs @ precision
    dd = (pd * dirs).sum(-1)
    tau = (pd * (mu - origin)).sum(-1) / dd
    return tau, dd


def mahalanobis(points, mu, precision):
    v = points - mu
    return ((v @ precision) * v).sum(-1)


def gut(w, cam, origin, dirs):
    """3DGUT (000 §A.1.2)."""
    mu, log_scale, q, logit, sh = unpack(w)
    R, t = cam["R"], cam["t"]
    rot, scale = quaternion_matrix(q), torch.exp(log_scale)
    # The unscented transform: sigma points mu and mu +- sqrt(3) s_i r_i (n = 3, lambda = 0).
    offsets = math.sqrt(3.0) * (rot * scale).T
    points = torch.cat([mu[None], mu + offsets, mu - offsets])
    seen = points @ R.T + t
    y = project(cam, seen)
    wm = torch.tensor([0.0] + [1.0 / 6.0] * 6)
    wc = torch.tensor([2.0] + [1.0 / 6.0] * 6)
    mean2d = (wm[:, None] * y).sum(0)
    e = y - mean2d
    cov = (wc[:, None, None] * e[:, :, None] * e[:, None, :]).sum(0)
    det = cov[0, 0] * cov[1, 1] - cov[0, 1] ** 2
    det_filtered = (cov[0, 0] + FILTER) * (cov[1, 1] + FILTER) - cov[0, 1] ** 2
    opacity = torch.sigmoid(logit) * torch.sqrt(torch.clamp_min(det, 0.0) / det_filtered)
    with torch.no_grad():
        kept = (
            all(projectable(cam, s.numpy()) and np.linalg.norm(s.numpy()) > NEAR for s in seen)
            and det_filtered.item() > 0
            and opacity.item() >= ALPHA_MIN
        )
    # Eq. 1: the largest response on the ray, which starts at the camera (tau >= 0).
    precision = rot @ torch.diag(scale**-2) @ rot.T
    tau, _ = closest_on_ray(origin, dirs, mu, precision)
    tau = torch.clamp_min(tau, 0.0)
    power = mahalanobis(origin + tau[:, None] * dirs, mu, precision)
    alpha = opacity * torch.exp(-0.5 * power)
    return torch.linalg.norm(seen[0]), kept, sh_color(sh, mu - origin), alpha


def normal_cdf(s):
    return 0.5 * torch.erfc(-s / math.sqrt(2.0))


def geer(w, cam, origin, dirs):
    """3DGEER (003 App. B): the ray integral from the camera, exp(-D^2 / 2) Phi(s*)."""
    mu, log_scale, q, logit, sh = unpack(w)
    R, t = cam["R"], cam["t"]
    rot, scale = quaternion_matrix(q), torch.exp(log_scale)
    precision = rot @ torch.diag(scale**-2) @ rot.T
    # The whole line's closest point to the mean (Mahalanobis): D^2 there, and how far along
    # the ray it lies in canonical units (|d_u| = sqrt(d^T Sigma^-1 d)).
    tau, dd = closest_on_ray(origin, dirs, mu, precision)
    d2 = mahalanobis(origin + tau[:, None] * dirs, mu, precision)
    ahead = tau * torch.sqrt(dd)
    opacity = torch.sigmoid(logit)
    alpha = opacity * torch.exp(-0.5 * d2) * normal_cdf(ahead)
    mean = R @ mu + t
    with torch.no_grad():
        kept = (
            torch.linalg.norm(mean).item() > NEAR
            and projectable(cam, mean.numpy())
            and opacity.item() >= ALPHA_MIN
        )
    return torch.linalg.norm(mean), kept, sh_color(sh, mu - origin), alpha


def l1_interval(a, b):
    """For each row, the interval of tau where sum_k |a_k + b_k tau| <= 1 (a, b: P x 3), as
    differentiable (enter, exit) and whether it is non-empty. The norm is convex and linear
    between its breakpoints -a_k / b_k: the ends are located among the breakpoints (no
    gradient), then solved on their segment, where every sign is fixed."""
    an, bn = a.detach().numpy(), b.detach().numpy()
    breaks = -an / bn
    value = np.abs(an[:, None, :] + bn[:, None, :] * breaks[:, :, None]).sum(-1)
    inside = value <= 1
    hit = inside.any(-1)
    big = np.abs(breaks).max(-1) + 1.0
    ends = []
    for away in (-1.0, 1.0):
        # The outermost breakpoint inside on this side, the next one out, and a point between
        # them (or past the last): the norm's signs on the segment that holds the end.
        last = np.where(inside, away * breaks, -np.inf).max(-1) * away
        out = np.where(away * (breaks - last[:, None]) > 0, away * breaks, np.inf).min(-1) * away
        probe = np.where(np.isfinite(out), 0.5 * (last + out), last + away * big)
        # A miss: the signs of the norm's far slopes, so the formula stays finite.
        signs = np.where(hit[:, None], np.sign(an + bn * probe[:, None]), away * np.sign(bn))
        s = torch.tensor(signs)
        ends.append((1 - (s * a).sum(-1)) / (s * b).sum(-1))
    return ends[0], ends[1], torch.tensor(hit)


def linprim(w, cam, origin, pixels):
    """LinPrim (000 §A.1.3) on the pinhole: Beer-Lambert through the linearized octahedron."""
    mu, log_scale, q, logit, sh = unpack(w)
    R, t, f, c = cam["R"], cam["t"], cam["focal"], cam["principal"]
    half_extents = torch.exp(log_scale + math.log(2.0))
    mean = R @ mu + t
    x, y, z = mean
    dist = torch.linalg.norm(mean)
    centre = f * torch.stack([x / z, y / z]) + c
    # The pinhole's Jacobian, and the distance's gradient as the third row.
    J = torch.stack(
        [
            torch.stack([f[0] / z, torch.zeros(()), -f[0] * x / z**2]),
            torch.stack([torch.zeros(()), f[1] / z, -f[1] * y / z**2]),
            mean / dist,
        ]
    )
    A = J @ R @ quaternion_matrix(q) @ torch.diag(half_extents)
    inverse = torch.linalg.inv(A)
    # ||inverse (p - centre, tau)||_1 = sum_k |a_k + b_k tau|.
    a = (pixels - centre) @ inverse[:, :2].T
    b = inverse[:, 2].expand_as(a)
    enter, exit_, hit = l1_interval(a, b)
    chord = torch.where(hit & (exit_ > enter), exit_ - enter, torch.zeros(()))
    o = torch.clamp_max(torch.sigmoid(logit), 0.999)
    density = -torch.log(1 - 0.99 * o) / (2 * half_extents.min())
    alpha = 1 - torch.exp(-density * chord)
    with torch.no_grad():
        half_fov = torch.maximum(cam["size"] - c, c) / f
        kept = (
            z.item() > NEAR
            and bool((torch.abs(mean[:2] / z) <= 1.3 * half_fov).all())
            and abs(torch.linalg.det(A).item()) > 1e-30
        )
    return dist, kept, sh_color(sh, mu - origin), alpha


METHODS = {"gut": gut, "geer": geer, "linprim": linprim}


# --- The blend (gsplat's rule, with our 0.99 clamp) ------------------------------------------


def render(method, params, cam):
    """Color, alpha and expected depth (row-major, H x W) and each pixel's clearness."""
    width, height = cam["size_px"]
    ys, xs = torch.meshgrid(torch.arange(height), torch.arange(width), indexing="ij")
    pixels = torch.stack([xs.reshape(-1), ys.reshape(-1)], -1).to(torch.float64) + 0.5
    R, t = cam["R"], cam["t"]
    origin = -(R.T @ t)
    per_pixel = pixels if method == "linprim" else ray(cam, pixels) @ R
    prims = [METHODS[method](params[i], cam, origin, per_pixel) for i in range(params.shape[0])]
    order = sorted(range(len(prims)), key=lambda i: (prims[i][0].item(), i))
    count = pixels.shape[0]
    T = torch.ones(count)
    color = torch.zeros(count, 3)
    weighted_depth = torch.zeros(count)
    done = torch.zeros(count, dtype=torch.bool)
    clear = torch.ones(count, dtype=torch.bool)
    for i in order:
        depth, kept, rgb, raw = prims[i]
        if not kept:
            continue
        alpha = torch.clamp_max(raw, ALPHA_MAX)
        with torch.no_grad():
            near_min = (raw / ALPHA_MIN - 1).abs() <= ALPHA_MARGIN
            near_max = (raw / ALPHA_MAX - 1).abs() <= ALPHA_MARGIN
            clear &= ~(~done & (near_min | near_max))
            take = ~done & (alpha >= ALPHA_MIN)
            next_t = T * (1 - alpha)
            stop = take & (next_t <= T_MIN)
            clear &= ~(take & ((next_t / T_MIN - 1).abs() <= T_MARGIN))
            done |= stop
            take &= ~stop
        w = torch.where(take, alpha * T, torch.zeros(()))
        color = color + w[:, None] * rgb
        weighted_depth = weighted_depth + w * depth
        T = torch.where(take, T * (1 - alpha), T)
    alpha = 1 - T
    safe = torch.where(alpha > 0, alpha, torch.ones(()))
    depth = torch.where(alpha > 0, weighted_depth / safe, torch.zeros(()))
    dropped = sum(1 for p in prims if not p[1])
    return color.reshape(-1), alpha, depth, clear, dropped


# --- Brute-force checks of the closed forms -----------------------------------------------


def self_check():
    """Each closed form against brute force on random Gaussians and rays, and each camera's ray
    against its projection; raises on a mismatch."""
    rng = np.random.default_rng(7)
    s2pi = math.sqrt(2 * math.pi)
    for _ in range(20):
        mu = torch.tensor(rng.normal(size=3) + [0, 0, 4])
        rot = quaternion_matrix(torch.tensor(rng.normal(size=4)))
        scale = torch.tensor(np.exp(rng.normal(size=3) * 0.5 - 1))
        precision = rot @ torch.diag(scale**-2) @ rot.T
        origin = torch.tensor(rng.normal(size=3) * 0.3)
        d = mu - origin + torch.tensor(rng.normal(size=3) * 0.3)
        d = (d / torch.linalg.norm(d))[None]
        # 3DGUT: the largest response over the ray's points, by a dense search.
        taus = torch.linspace(0, 20, 400001)
        q = mahalanobis(origin + taus[:, None] * d, mu, precision)
        tau, dd = closest_on_ray(origin, d, mu, precision)
        best = mahalanobis(origin + torch.clamp_min(tau, 0)[:, None] * d, mu, precision)
        assert abs(q.min() - best[0]) <= 1e-6 * (1 + best[0]), (q.min(), best)
        # 3DGEER: the integral of the canonical density along the ray (Simpson), per unit of
        # canonical length (|d_u| per unit of tau).
        density = torch.exp(-0.5 * q) / s2pi * torch.sqrt(dd)
        h = taus[1] - taus[0]
        ends = density[0] + density[-1]
        integral = h / 3 * (ends + 4 * density[1:-1:2].sum() + 2 * density[2:-1:2].sum())
        d2 = mahalanobis(origin + tau[:, None] * d, mu, precision)
        closed = torch.exp(-0.5 * d2) * normal_cdf(tau * torch.sqrt(dd))
        assert abs(integral - closed[0]) <= 1e-9, (integral, closed)
    # LinPrim: the interval's length against a dense sampling of the L1 condition.
    for _ in range(200):
        a = torch.tensor(rng.normal(size=(1, 3)) * 0.5)
        b = torch.tensor(rng.normal(size=(1, 3)))
        enter, exit_, hit = l1_interval(a, b)
        taus = torch.linspace(-20, 20, 400001)
        inside = (torch.abs(a + taus[:, None] * b).sum(-1) <= 1).to(torch.float64)
        sampled = inside.sum() * (taus[1] - taus[0])
        chord = (exit_ - enter).clamp_min(0) if hit[0] else torch.zeros(1)
        assert abs(sampled - chord[0]) <= 2e-4, (sampled, chord, a, b)
    # Each camera: the ray through a pixel projects back onto it.
    for model in ("pinhole", "equiangular", "kannala_brandt"):
        cam = {
            "model": model,
            "focal": torch.tensor([20.0, 22.0]),
            "principal": torch.tensor([24.3, 23.7]),
            "distortion": torch.tensor([0.05, -0.01, 0.002, -0.0005]),
        }
        pixels = torch.tensor(rng.random((50, 2)) * 48)
        back = project(cam, ray(cam, pixels) * 3.0)
        assert torch.allclose(back, pixels, atol=1e-9), model


# --- Scenes -------------------------------------------------------------------------------


def rotation(rng, angle):
    """A rotation by `angle` radians about a random axis (Rodrigues)."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def scene(rng, cam, n, log_scale, depth, margin, logits=(-1.5, 3.5)):
    """`n` random Gaussians in front of `cam`, as our `Params` words: mean (3), log scale (3),
    rotation (w, x, y, z), opacity logit, SH (16 x 3). Each centre lies on the ray of a random
    point of the image (grown by `margin` px each side) at a distance in `depth`, its opacity
    logit in `logits`."""
    width, height = cam["size_px"]
    R, t = cam["R"].numpy(), cam["t"].numpy()
    gaussians = []
    while len(gaussians) < n:
        pixel = rng.random(2) * [width + 2 * margin, height + 2 * margin] - margin
        with torch.no_grad():
            d = ray(cam, torch.tensor(pixel)[None])[0].numpy()
        camera_space = d * (depth[0] + rng.random() * (depth[1] - depth[0]))
        mean = R.T @ (camera_space - t)
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        sh = (rng.random((16, 3)) - 0.5) * 0.8
        sh[0] = (rng.random(3) - 0.5) * 2.5
        words = np.concatenate(
            [
                mean,
                log_scale + rng.random(3) * 0.8,
                q,
                [logits[0] + rng.random() * (logits[1] - logits[0])],
                sh.reshape(-1),
            ]
        )
        gaussians.append(f32(words))
    return np.array(gaussians)


def case(name, method, camera, params, seed):
    rng = np.random.default_rng(seed)
    width, height = camera["size_px"]
    count = width * height
    leaves = ["R", "t", "focal", "principal"] + (["distortion"] if "distortion" in camera else [])
    cam = dict(camera)
    for key in leaves:
        cam[key] = camera[key].clone().requires_grad_(True)
    p = torch.tensor(params, requires_grad=True)
    color, alpha, depth, clear, dropped = render(method, p, cam)
    weights = {
        "color": f32(rng.random(count * 3) * 2 - 1),
        "alpha": f32(rng.random(count) * 2 - 1),
        "depth": f32((rng.random(count) * 2 - 1) * 0.1),
    }
    keep = clear.numpy().astype(np.float64)
    weights["color"] *= np.repeat(keep, 3)
    weights["alpha"] *= keep
    weights["depth"] *= keep
    loss = (
        (color * torch.tensor(weights["color"])).sum()
        + (alpha * torch.tensor(weights["alpha"])).sum()
        + (depth * torch.tensor(weights["depth"])).sum()
    )
    loss.backward()
    unclear = int((~clear).sum())
    print(
        f"{name}: {method} on {cam['model']}, {params.shape[0]} primitives ({dropped} dropped), "
        f"{width}x{height}, mean alpha {alpha.mean().item():.3f}, {unclear} pixels not clear"
    )
    fixture = {
        "method": method,
        "model": cam["model"],
        "camera": {
            "rotation_rows": camera["R"].tolist(),
            "translation": camera["t"].tolist(),
            "focal": camera["focal"].tolist(),
            "principal": camera["principal"].tolist(),
            "size": [width, height],
        },
        "params": params.tolist(),
        "weights": {k: v.tolist() for k, v in weights.items()},
        "clear": clear.numpy().astype(int).tolist(),
        "color": color.detach().tolist(),
        "alpha": alpha.detach().tolist(),
        "depth": depth.detach().tolist(),
        "gradient": {
            "params": p.grad.tolist(),
            "rotation_rows": cam["R"].grad.tolist(),
            "translation": cam["t"].grad.tolist(),
            "focal": cam["focal"].grad.tolist(),
            "principal": cam["principal"].grad.tolist(),
        },
    }
    if "distortion" in camera:
        fixture["camera"]["distortion"] = camera["distortion"].tolist()
        fixture["gradient"]["distortion"] = cam["distortion"].grad.tolist()
    return fixture


def main():
    self_check()
    generator = (
        f"methods/tests/first_principles/make_fixtures.py, torch {torch.__version__}, float64"
    )
    rng = np.random.default_rng(56)

    def camera(model, width, height, focal, principal, angle, distortion=None):
        cam = {
            "model": model,
            "R": torch.tensor(f32(rotation(rng, angle))),
            "t": torch.tensor(f32(rng.normal(size=3) * 0.3)),
            "focal": torch.tensor(f32(focal)),
            "principal": torch.tensor(f32(principal)),
            "size": torch.tensor([float(width), float(height)]),
            "size_px": (width, height),
        }
        if distortion is not None:
            cam["distortion"] = torch.tensor(f32(distortion))
        return cam

    def near(cam, far, log_scale, depth):
        """`far` and four faint Gaussians near the camera, a sigma or two away: rays that
        start inside their tails (3DGEER's Phi(s*) below 1, 3DGUT's tau_max clamped at 0)."""
        return np.concatenate([far, scene(rng, cam, 4, log_scale, depth, 0.0, (-2.5, -0.5))])

    def beside(cam, params, polar, distance):
        """`params` and a faint Gaussian `distance` from the camera, `polar` radians off its
        axis toward the image's corner: forward rays pass it with their closest point behind
        the camera (3DGUT's tau_max clamped at 0)."""
        side = math.sin(polar) / math.sqrt(2)
        d = np.array([side, side, math.cos(polar)])
        R, t = cam["R"].numpy(), cam["t"].numpy()
        mean = R.T @ (d * distance - t)
        shape = [-1.5, -1.3, -1.4], [0.9, 0.2, -0.3, 0.1], [-1.0]
        words = np.concatenate([mean, *shape, params[0, 11:]])
        return np.concatenate([params, f32(words)[None]])

    fisheye_k = [0.05, -0.01, 0.002, -0.0005]
    cases = []
    # 3DGUT, SH degree 3: a turned and moved pinhole, fx != fy, the principal point off centre.
    cam = camera("pinhole", 48, 32, [52.0, 47.5], [25.3, 14.6], 0.4)
    far = scene(rng, cam, 44, -2.2, (2.0, 6.0), 4.0)
    cases.append(("gut_pinhole", "gut", cam, near(cam, far, -1.9, (0.7, 1.2))))
    # 3DGUT through the equiangular (BEAP) model, 140 x 95 degrees.
    cam = camera("equiangular", 48, 32, [20.0, 19.5], [24.4, 15.7], 0.3)
    far = scene(rng, cam, 44, -1.7, (2.0, 5.0), 2.0)
    cases.append(("gut_equiangular", "gut", cam, near(cam, far, -1.9, (0.7, 1.2))))
    # 3DGUT through a Kannala-Brandt fisheye with distortion, about 190 degrees across the
    # diagonal.
    cam = camera("kannala_brandt", 40, 40, [15.0, 15.5], [20.3, 19.6], 0.3, fisheye_k)
    far = scene(rng, cam, 46, -1.5, (2.0, 5.0), 2.0)
    params = beside(cam, near(cam, far, -1.9, (0.7, 1.2)), 1.4, 0.5)
    cases.append(("gut_fisheye", "gut", cam, params))
    # 3DGEER on the pinhole.
    cam = camera("pinhole", 48, 32, [50.0, 52.5], [23.7, 16.4], 0.35)
    far = scene(rng, cam, 44, -2.2, (2.0, 6.0), 4.0)
    cases.append(("geer_pinhole", "geer", cam, near(cam, far, -1.6, (0.4, 0.9))))
    # 3DGEER on the equiangular model.
    cam = camera("equiangular", 48, 32, [20.0, 21.0], [23.6, 16.2], 0.25)
    far = scene(rng, cam, 44, -1.7, (2.0, 5.0), 2.0)
    cases.append(("geer_equiangular", "geer", cam, near(cam, far, -1.6, (0.4, 0.9))))
    # 3DGEER through the fisheye.
    cam = camera("kannala_brandt", 40, 40, [15.5, 15.0], [19.7, 20.4], 0.3, fisheye_k)
    far = scene(rng, cam, 46, -1.5, (2.0, 5.0), 2.0)
    cases.append(("geer_fisheye", "geer", cam, near(cam, far, -1.6, (0.4, 0.9))))
    # LinPrim (pinhole only): octahedra with half-extents 2x the scales.
    cam = camera("pinhole", 48, 32, [48.0, 50.0], [24.6, 15.3], 0.3)
    cases.append(("linprim_pinhole", "linprim", cam, scene(rng, cam, 60, -2.4, (2.0, 6.0), 2.0)))

    for i, (name, method, cam, params) in enumerate(cases):
        fixture = case(name, method, cam, params, 100 + i)
        fixture["generator"] = generator
        fixture["sh_coefficients"] = 16
        path = OUT / f"{name}.json"
        tmp = path.with_suffix(".json.partial")
        tmp.write_text(json.dumps(fixture, separators=(",", ":")) + "\n")
        tmp.replace(path)


if __name__ == "__main__":
    main()
