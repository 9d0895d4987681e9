"""Independent references for 3DGS and 2D Gaussian surfels: images and gradients from gsplat's
pure-PyTorch implementation, in float64, committed as fixtures that
`methods/tests/independent_reference.rs` (3DGS) and the user crate `examples/surfels` (2DGS,
`tests/gsplat_2dgs.json`, `render_2dgs` says what comes from gsplat there) compare the CPU and
GPU pipelines against.

What comes from gsplat (`gsplat/cuda/_torch_impl.py` of the release named below, loaded from
its wheel without importing the package, which would build CUDA kernels): the quaternion and
scale to covariance, the world-to-camera transform, the pinhole projection (with its tangent
clamp) and the equidistant fisheye projection, the 0.3 px dilation and conic, the antialiasing
compensation, the spherical harmonics (Sloan's bases) and the Gaussian's alpha at a pixel
centre. The blend is written here from gsplat's CUDA rule (its `accumulate` needs nerfacc and
its tile walk the CUDA extension): every valid Gaussian at every pixel in depth order, pairs
below 1/255 skipped, the walk stopped before the pair that would take T to 1e-4 or below.
Gradients are torch's autograd of a random linear loss on color, alpha and expected depth.

Our conventions where gsplat has a choice (splat's DESIGN.md §6 and `methods/src/gs3d.rs`):
alpha clamped at 0.99 (INRIA's; gsplat's is 0.999), and the camera centre for the SH directions
as -R^T t (gsplat inverts the view matrix: the same point, but as a function of R's nine
entries its derivative differs off the rotation group, and the check differentiates by entry).

A pixel is *clear* when no decision the blend takes there is within a margin of its threshold:
no pair's alpha within 1e-4 (relative) of 1/255 or of the 0.99 clamp, no T-stop within 1e-3
(relative) of 1e-4. The loss weights are zero off the clear pixels and the image comparison
skips them, so a pair an f32 renderer decides the other way cannot fail the check; the test
refuses a fixture where more than 2% of the pixels are not clear.

Run from the repository root (torch from PyPI runs on the CPU):

    pip install torch==2.9.1 && pip download gsplat==1.5.3 --no-deps -d /tmp/gsplat
    python3 methods/tests/gsplat/make_fixtures.py /tmp/gsplat/gsplat-1.5.3-py3-none-any.whl
"""

import importlib.util
import json
import math
import pathlib
import sys
import types
import zipfile

import numpy as np
import torch

torch.set_default_dtype(torch.float64)

ALPHA_MIN = 1.0 / 255.0
ALPHA_MAX = 0.99
T_MIN = 1e-4
NEAR = 0.01
ALPHA_MARGIN = 1e-4
T_MARGIN = 1e-3

OUT = pathlib.Path(__file__).parent
SURFELS = OUT.parents[2] / "examples" / "surfels" / "tests"


def load_gsplat(wheel):
    """gsplat's `_torch_impl.py` and `_torch_impl_2dgs.py` from its wheel, as modules of their
    own (the second imports the first by its package path, which is given it here)."""
    with zipfile.ZipFile(wheel) as z:
        source = z.read("gsplat/cuda/_torch_impl.py").decode()
        source_2dgs = z.read("gsplat/cuda/_torch_impl_2dgs.py").decode()
        version = next(n for n in z.namelist() if n.endswith(".dist-info/METADATA"))
        version = next(
            line.split(":", 1)[1].strip()
            for line in z.read(version).decode().splitlines()
            if line.startswith("Version:")
        )

    def module(name, source, path):
        spec = importlib.util.spec_from_loader(name, loader=None)
        m = importlib.util.module_from_spec(spec)
        exec(compile(source, path, "exec"), m.__dict__)
        return m

    g = module("gsplat_torch_impl", source, "gsplat/cuda/_torch_impl.py")
    for package in ("gsplat", "gsplat.cuda"):
        sys.modules.setdefault(package, types.ModuleType(package))
    sys.modules["gsplat.cuda._torch_impl"] = g
    g2 = module("gsplat_torch_impl_2dgs", source_2dgs, "gsplat/cuda/_torch_impl_2dgs.py")
    return g, g2, version


def f32(a):
    """Values an f32 renderer can take as they are."""
    return np.asarray(a, dtype=np.float32).astype(np.float64)


def rotation(rng, angle):
    """A rotation by `angle` radians about a random axis (Rodrigues)."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def scene(rng, camera, n, sh_coefficients, log_scale, spread, depth, off_axis=0.0):
    """`n` random Gaussians in front of `camera`, as our `Params` words per Gaussian:
    mean (3), log scale (3), rotation (w, x, y, z), opacity logit, SH (16 x 3; zero past the
    method's degree). `off_axis` keeps each centre at least that far from the optical axis
    (camera-space x and y, relative to the depth)."""
    r, t = camera["R"], camera["t"]
    gaussians = []
    while len(gaussians) < n:
        z = depth[0] + rng.random() * (depth[1] - depth[0])
        u = (rng.random(2) - 0.5) * 2 * spread
        if min(abs(u[0]), abs(u[1])) < off_axis:
            continue
        camera_space = np.array([u[0] * z, u[1] * z, z])
        mean = r.T @ (camera_space - t)
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        sh = np.zeros((16, 3))
        sh[:sh_coefficients] = (rng.random((sh_coefficients, 3)) - 0.5) * 0.8
        sh[0] = (rng.random(3) - 0.5) * 2.5
        words = np.concatenate(
            [
                mean,
                log_scale + rng.random(3) * 0.8,
                q,
                [rng.random() * 5.0 - 1.5],
                sh.reshape(-1),
            ]
        )
        gaussians.append(f32(words))
    return np.array(gaussians)


def quaternion(m):
    """The unit quaternion (w, x, y, z) of the rotation matrix `m`."""
    w = math.sqrt(max(0.0, 1 + m[0, 0] + m[1, 1] + m[2, 2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1 + m[0, 0] - m[1, 1] - m[2, 2])) / 2, m[2, 1] - m[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1 - m[0, 0] + m[1, 1] - m[2, 2])) / 2, m[0, 2] - m[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1 - m[0, 0] - m[1, 1] + m[2, 2])) / 2, m[1, 0] - m[0, 1])
    return np.array([w, x, y, z])


def surfels(rng, camera, n):
    """`n` random surfels in front of `camera` in `examples/surfels`' words, each disk turned up
    to 1.1 rad from facing the camera (never edge-on, where the ray-splat intersection
    divides by zero)."""
    r, t = camera["R"], camera["t"]
    out = []
    for _ in range(n):
        z = 2.0 + rng.random() * 4.0
        u = (rng.random(2) - 0.5) * 1.1
        mean = r.T @ (np.array([u[0] * z, u[1] * z, z]) - t)
        axes = r.T @ rotation(rng, rng.random() * 1.1)
        sh = (rng.random((4, 3)) - 0.5) * 0.8
        sh[0] = (rng.random(3) - 0.5) * 2.5
        words = np.concatenate(
            [mean, -2.2 + rng.random(2) * 0.9, quaternion(axes), [rng.random() * 5.0 - 1.5], sh.reshape(-1)]
        )
        out.append(f32(words))
    return np.array(out)


def view_and_intrinsics(cam):
    """gsplat's world-to-camera matrix and intrinsics (one camera), differentiable in `cam`."""
    fx, fy, cx, cy = cam["focal"][0], cam["focal"][1], cam["principal"][0], cam["principal"][1]
    viewmat = torch.zeros(1, 4, 4)
    viewmat[0, :3, :3] = cam["R"]
    viewmat[0, :3, 3] = cam["t"]
    viewmat[0, 3, 3] = 1.0
    K = torch.zeros(1, 3, 3)
    K[0, 0, 0], K[0, 1, 1], K[0, 0, 2], K[0, 1, 2], K[0, 2, 2] = fx, fy, cx, cy, 1.0
    return viewmat, K


def render(g, params, cam, sh_coefficients, antialiased, model):
    """Color, alpha and expected depth (row-major, H x W) and each pixel's clearness."""
    n = params.shape[0]
    means, log_scales = params[:, 0:3], params[:, 3:6]
    quats, logits = params[:, 6:10], params[:, 10]
    sh = params[:, 11:].reshape(n, 16, 3)[:, :sh_coefficients]
    R, t = cam["R"], cam["t"]
    width, height = cam["size"]
    viewmat, K = view_and_intrinsics(cam)
    covars, _ = g._quat_scale_to_covar_preci(quats, torch.exp(log_scales), compute_preci=False)
    _, means2d, depths, conics, compensations = g._fully_fused_projection(
        means,
        covars,
        viewmat,
        K,
        width,
        height,
        eps2d=0.3,
        near_plane=NEAR,
        calc_compensations=antialiased,
        camera_model=model,
    )
    means2d, depths, conics = means2d[0], depths[0], conics[0]
    opacities = torch.sigmoid(logits)
    if antialiased:
        opacities = opacities * compensations[0]
    campos = -(R.T @ t)
    colors = g._spherical_harmonics(
        int(math.isqrt(sh_coefficients)) - 1, means - campos, sh
    )
    colors = torch.clamp_min(colors + 0.5, 0.0)

    # gsplat's validity before its screen-box cull (which, at 3.33 sigma, cuts nothing the
    # 1/255 threshold keeps): in front of the near plane with a positive determinant.
    det = conics[:, 0] * conics[:, 2] - conics[:, 1] ** 2
    valid = (depths > NEAR) & (det > 0)

    def alpha_at(i, pixels):
        d = pixels - means2d[i]
        c = conics[i]
        power = 0.5 * (c[0] * d[:, 0] ** 2 + c[2] * d[:, 1] ** 2) + c[1] * d[:, 0] * d[:, 1]
        return opacities[i] * torch.exp(-power), power >= 0

    return composite(width, height, depths, valid, alpha_at, colors)


def render_2dgs(g, g2, params, cam):
    """2D Gaussian surfels (degree-1 SH), as `examples/surfels` words them: mean (3), log scale
    of the two tangent axes (2), rotation (w, x, y, z), opacity logit, SH (4 x 3). The ray
    transform and the ray-splat intersection are gsplat's (`_fully_fused_projection_2dgs`,
    `accumulate_2dgs`), so is the low-pass filter's 2 |d|^2 with the smaller of the two taken;
    the filter sits on the projected centre, as in the 2DGS paper (gsplat's sits on the centre
    of the ellipse's box, which perspective moves off it)."""
    n = params.shape[0]
    means, log_scales = params[:, 0:3], params[:, 3:5]
    quats, logits, sh = params[:, 5:9], params[:, 9], params[:, 10:22].reshape(n, 4, 3)
    R, t = cam["R"], cam["t"]
    width, height = cam["size"]
    viewmat, K = view_and_intrinsics(cam)
    # The third scale only sets the normal's length, which the image does not read.
    scales = torch.cat([torch.exp(log_scales), torch.ones(n, 1)], dim=-1)
    _, _, depths, ray_transforms, _ = g2._fully_fused_projection_2dgs(
        means, quats, scales, viewmat, K, width, height, near_plane=NEAR
    )
    depths, M = depths[0], ray_transforms[0]
    centers = M[:, :2, 2] / M[:, 2:3, 2]
    opacities = torch.sigmoid(logits)
    campos = -(R.T @ t)
    colors = torch.clamp_min(g._spherical_harmonics(1, means - campos, sh) + 0.5, 0.0)
    valid = depths > NEAR

    def alpha_at(i, pixels):
        x, y = pixels[:, 0:1], pixels[:, 1:2]
        h_u = -M[i, 0, :] + M[i, 2, :] * x
        h_v = -M[i, 1, :] + M[i, 2, :] * y
        k = torch.cross(h_u, h_v, dim=-1)
        disk = (k[:, 0] / k[:, 2]) ** 2 + (k[:, 1] / k[:, 2]) ** 2
        d = pixels - centers[i]
        filtered = 2 * (d[:, 0] ** 2 + d[:, 1] ** 2)
        return opacities[i] * torch.exp(-0.5 * torch.minimum(disk, filtered)), disk >= 0

    return composite(width, height, depths, valid, alpha_at, colors)


def composite(width, height, depths, valid, alpha_at, colors):
    """gsplat's blend (see the module): color, alpha and expected depth (row-major, H x W) and
    each pixel's clearness. `alpha_at(i, pixels)` is primitive i's alpha before the clamp at
    the pixel centres, and where it may be taken at all."""
    n = depths.shape[0]
    ys, xs = torch.meshgrid(torch.arange(height), torch.arange(width), indexing="ij")
    pixels = torch.stack([xs.reshape(-1), ys.reshape(-1)], -1) + 0.5
    order = sorted(range(n), key=lambda i: (depths[i].item(), i))
    count = pixels.shape[0]
    T = torch.ones(count)
    color = torch.zeros(count, 3)
    weighted_depth = torch.zeros(count)
    done = torch.zeros(count, dtype=torch.bool)
    clear = torch.ones(count, dtype=torch.bool)
    for i in order:
        if not valid[i]:
            continue
        raw, allowed = alpha_at(i, pixels)
        alpha = torch.clamp_max(raw, ALPHA_MAX)
        with torch.no_grad():
            near_min = (raw / ALPHA_MIN - 1).abs() <= ALPHA_MARGIN
            near_max = (raw / ALPHA_MAX - 1).abs() <= ALPHA_MARGIN
            clear &= ~(~done & (near_min | near_max))
            take = ~done & allowed & (alpha >= ALPHA_MIN)
            next_t = T * (1 - alpha)
            stop = take & (next_t <= T_MIN)
            clear &= ~(take & ((next_t / T_MIN - 1).abs() <= T_MARGIN))
            done |= stop
            take &= ~stop
        w = torch.where(take, alpha * T, torch.zeros(()))
        color = color + w[:, None] * colors[i]
        weighted_depth = weighted_depth + w * depths[i]
        T = torch.where(take, T * (1 - alpha), T)
    alpha = 1 - T
    safe = torch.where(alpha > 0, alpha, torch.ones(()))
    depth = torch.where(alpha > 0, weighted_depth / safe, torch.zeros(()))
    return color.reshape(-1), alpha, depth, clear


def case(name, method, camera, params, draw, model, seed):
    """The fixture of `params` seen by `camera`, drawn by `draw(p, cam)` (a render function's
    color, alpha, depth and clearness), with the gradients of a random linear loss."""
    rng = np.random.default_rng(seed)
    width, height = camera["size"]
    count = width * height
    cam = {
        "R": torch.tensor(camera["R"], requires_grad=True),
        "t": torch.tensor(camera["t"], requires_grad=True),
        "focal": torch.tensor(camera["focal"], requires_grad=True),
        "principal": torch.tensor(camera["principal"], requires_grad=True),
        "size": (width, height),
    }
    p = torch.tensor(params, requires_grad=True)
    color, alpha, depth, clear = draw(p, cam)
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
        f"{name}: {params.shape[0]} primitives, {width}x{height}, mean alpha "
        f"{alpha.mean().item():.3f}, {unclear} pixels not clear"
    )
    fixture = {
        "method": method,
        "model": {"pinhole": "pinhole", "fisheye": "kannala_brandt"}[model],
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
    return fixture


def main():
    g, g2, version = load_gsplat(sys.argv[1])
    generator = f"gsplat {version} cuda/_torch_impl.py, torch {torch.__version__}, float64"
    rng = np.random.default_rng(56)

    def pinhole(width, height, focal, principal, angle):
        R = f32(rotation(rng, angle))
        return {
            "R": R,
            "t": f32(rng.normal(size=3) * 0.3),
            "focal": f32(focal),
            "principal": f32(principal),
            "size": (width, height),
        }

    cases = []
    # SH degree 3, a turned and moved camera, fx != fy and the principal point off centre.
    cam = pinhole(48, 32, [52.0, 47.5], [25.3, 14.6], 0.4)
    cases.append(("pinhole_sh3", "gs3d", cam, scene(rng, cam, 48, 16, -2.2, 0.55, (2.0, 6.0)), 16, False, "pinhole"))
    # SH degree 0, a dense stack: many pixels stop at the T-stop.
    cam = pinhole(32, 32, [40.0, 40.0], [16.0, 16.0], 0.2)
    cases.append(("pinhole_sh0_dense", "gs3d_sh0", cam, scene(rng, cam, 90, 1, -1.6, 0.35, (2.0, 4.0)), 1, False, "pinhole"))
    # SH degree 1, Gaussians off the image's edges (the tangent clamp at work).
    cam = pinhole(40, 28, [36.0, 36.0], [21.0, 13.0], 0.3)
    cases.append(("pinhole_sh1_edges", "gs3d_sh1", cam, scene(rng, cam, 40, 4, -1.9, 0.9, (1.5, 5.0)), 4, False, "pinhole"))
    # Antialiased, with sub-pixel Gaussians that fade instead of growing.
    cam = pinhole(40, 32, [44.0, 44.0], [20.0, 16.0], 0.25)
    tiny = scene(rng, cam, 40, 16, -4.0, 0.5, (2.0, 6.0))
    cases.append(("antialiased_sh3", "gs3d_aa", cam, np.concatenate([tiny, scene(rng, cam, 24, 16, -2.2, 0.5, (2.0, 6.0))]), 16, True, "pinhole"))
    # The equidistant fisheye (gsplat's: Kannala-Brandt without distortion), 130 degrees
    # across; centres kept off the axes, where gsplat's 1e-7 guards would show.
    cam = pinhole(48, 48, [20.0, 20.0], [24.0, 24.0], 0.3)
    cases.append(("fisheye_sh3", "gs3d", cam, scene(rng, cam, 50, 16, -1.1, 1.3, (2.0, 5.0), off_axis=0.15), 16, False, "fisheye"))

    for i, (name, method, cam, params, sh_coefficients, antialiased, model) in enumerate(cases):

        def draw(p, c, sh_coefficients=sh_coefficients, antialiased=antialiased, model=model):
            return render(g, p, c, sh_coefficients, antialiased, model)

        fixture = case(name, method, cam, params, draw, model, 100 + i)
        fixture["generator"] = generator
        fixture["sh_coefficients"] = sh_coefficients
        write(OUT / f"{name}.json", fixture)

    # 2D Gaussian surfels (`examples/surfels`, a user crate of its own, holds its method to
    # this), their words its own; their own generator, so the fixtures above stay as they are.
    rng = np.random.default_rng(2024)
    cam = pinhole(48, 32, [50.0, 48.0], [24.4, 15.3], 0.3)
    params = surfels(rng, cam, 40)

    def draw(p, c):
        return render_2dgs(g, g2, p, c)

    fixture = case("gsplat_2dgs", "surfel", cam, params, draw, "pinhole", 200)
    fixture["generator"] = f"gsplat {version} cuda/_torch_impl_2dgs.py, torch {torch.__version__}, float64"
    fixture["sh_coefficients"] = 4
    fixture["words"] = "params"
    write(SURFELS / "gsplat_2dgs.json", fixture)


def write(path, fixture):
    """`fixture` as JSON at `path`, whole or not at all."""
    tmp = path.with_suffix(".json.partial")
    tmp.write_text(json.dumps(fixture, separators=(",", ":")) + "\n")
    tmp.replace(path)


if __name__ == "__main__":
    main()
