"""gsplat 1.5.3's 3DGS (DefaultStrategy, Adam, 0.8 L1 + 0.2 D-SSIM, black background) trained
from the same start as `splat fit`, for the quality and speed comparison of issue 12.

Usage: gsplat_fit.py DATA STEPS [POINTS=100000] [INIT_EXTENT=3] [EVAL_EVERY=0] [RENDERS_DIR]

`shared/bench/gsplat_train.py` with the two constants it fixes for one dataset taken from the
data instead, as gsplat's simple_trainer and `splat fit` both do: the scene scale is 1.1 times
the cameras' largest distance from their centre, and the random start is POINTS points in a
cube of half-side INIT_EXTENT times that scale around the cameras' centre, random colors,
opacity 0.1, each sized by the RMS distance to its 3 nearest neighbours. Prints the time per
step (the training loop, with the evaluations every EVAL_EVERY steps when asked) and the test PSNR and SSIM before and after (mean over views, the
render clamped to [0, 1]), as `splat fit` reports them.
"""
import json, math, sys, time

import numpy as np
import torch
import torch.nn.functional as F
from PIL import Image
from gsplat import rasterization
from gsplat.strategy import DefaultStrategy
from sklearn.neighbors import NearestNeighbors

torch.manual_seed(0)
np.random.seed(0)
root, steps = sys.argv[1], int(sys.argv[2])
points = int(sys.argv[3]) if len(sys.argv) > 3 else 100_000
init_extent = float(sys.argv[4]) if len(sys.argv) > 4 else 3.0
eval_every = int(sys.argv[5]) if len(sys.argv) > 5 else 0
renders = sys.argv[6] if len(sys.argv) > 6 else None


def load(split):
    d = json.load(open(f'{root}/transforms_{split}.json'))
    ims, c2ws = [], []
    for fr in d['frames']:
        im = np.asarray(Image.open(f"{root}/{fr['file_path']}.png"), np.float32) / 255.0
        ims.append(im[..., :3] * im[..., 3:4])  # on black
        c2ws.append(np.array(fr['transform_matrix'], np.float32))
    H, W = ims[0].shape[:2]
    f = 0.5 * W / math.tan(0.5 * d['camera_angle_x'])
    K = torch.tensor([[f, 0, W / 2], [0, f, H / 2], [0, 0, 1]], dtype=torch.float32, device='cuda')
    c2w = torch.tensor(np.stack(c2ws), device='cuda') @ torch.diag(torch.tensor([1.0, -1, -1, 1], device='cuda'))  # OpenGL -> OpenCV
    return torch.tensor(np.stack(ims), device='cuda'), torch.linalg.inv(c2w), K, W, H, c2w


tr_img, tr_vm, K, W, H, tr_c2w = load('train')
te_img, te_vm, _, _, _, _ = load('test')
centres = tr_c2w[:, :3, 3]
mid = centres.mean(0)
scene_scale = 1.1 * (centres - mid).norm(dim=1).max().item()
half = init_extent * scene_scale
xyz = (mid + (torch.rand(points, 3, device='cuda') * 2 - 1) * half).cpu().numpy()
dist, _ = NearestNeighbors(n_neighbors=4).fit(xyz).kneighbors(xyz)
size = np.sqrt(np.maximum((dist[:, 1:] ** 2).mean(-1), 1e-7))
C0 = 0.28209479177387814
params = torch.nn.ParameterDict({
    'means': torch.tensor(xyz, device='cuda'),
    'scales': torch.log(torch.tensor(size, dtype=torch.float32, device='cuda'))[:, None].repeat(1, 3),
    'quats': torch.tensor([[1.0, 0, 0, 0]], device='cuda').repeat(points, 1),
    'opacities': torch.logit(torch.full((points,), 0.1, device='cuda')),
    'sh0': ((torch.rand(points, 3, device='cuda') - 0.5) / C0)[:, None, :],
    'shN': torch.zeros(points, 15, 3, device='cuda')}).cuda()
lrs = {'means': 1.6e-4 * scene_scale, 'scales': 5e-3, 'quats': 1e-3, 'opacities': 5e-2, 'sh0': 2.5e-3, 'shN': 2.5e-3 / 20}
opt = {k: torch.optim.Adam([{'params': params[k], 'lr': lr, 'name': k}], eps=1e-15) for k, lr in lrs.items()}
sched = torch.optim.lr_scheduler.ExponentialLR(opt['means'], gamma=0.01 ** (1.0 / steps))
strategy = DefaultStrategy(verbose=False)
strategy.check_sanity(params, opt)
state = strategy.initialize_state(scene_scale=scene_scale)
print(f'{len(tr_img)} training and {len(te_img)} test views of {W}x{H}; scene scale {scene_scale:.3f}; '
      f'{points} random points in a cube of half-side {half:.3f}', flush=True)


def gauss_win(s=11, sigma=1.5):
    g = torch.exp(-((torch.arange(s, device='cuda') - s // 2) ** 2) / (2 * sigma ** 2))
    g = g / g.sum()
    return (g[:, None] * g[None, :]).expand(3, 1, s, s).contiguous()


WIN = gauss_win()


def ssim(a, b):
    a, b = a.permute(0, 3, 1, 2), b.permute(0, 3, 1, 2)
    mu_a, mu_b = F.conv2d(a, WIN, groups=3), F.conv2d(b, WIN, groups=3)
    saa = F.conv2d(a * a, WIN, groups=3) - mu_a ** 2
    sbb = F.conv2d(b * b, WIN, groups=3) - mu_b ** 2
    sab = F.conv2d(a * b, WIN, groups=3) - mu_a * mu_b
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    return (((2 * mu_a * mu_b + c1) * (2 * sab + c2)) / ((mu_a ** 2 + mu_b ** 2 + c1) * (saa + sbb + c2))).mean()


def render(vm, sh_deg):
    colors = torch.cat([params['sh0'], params['shN']], 1)
    return rasterization(params['means'], params['quats'], torch.exp(params['scales']), torch.sigmoid(params['opacities']),
                         colors, vm[None], K[None], W, H, sh_degree=sh_deg, packed=False, absgrad=False)


def evaluate(views=None, truth=None, save=False):
    views, truth = (te_vm, te_img) if views is None else (views, truth)
    with torch.no_grad():
        ps, ss = [], []
        for i in range(len(truth)):
            img = render(views[i], 3)[0].clamp(0, 1)
            ps.append(-10 * torch.log10(F.mse_loss(img, truth[i:i + 1])).item())
            ss.append(ssim(img, truth[i:i + 1]).item())
            if save and renders and i < 4:
                Image.fromarray((img[0].cpu().numpy() * 255 + 0.5).astype(np.uint8)).save(f'{renders}/gsplat_{i:03}.png')
    return np.mean(ps), np.mean(ss)


def report(step):
    """Test and training-view PSNR, and how many Gaussians are faint (where floaters hide)."""
    torch.cuda.synchronize()
    p, s = evaluate()
    pt, _ = evaluate(tr_vm[::8], tr_img[::8])
    o = torch.sigmoid(params['opacities'])
    print(f'  step {step}: test PSNR {p:.2f} dB, SSIM {s:.3f}; training views {pt:.2f} dB; {len(o)} gaussians, '
          f'{(o < 0.01).sum().item()} below opacity 0.01, {(o < 0.05).sum().item()} below 0.05', flush=True)


p0, s0 = evaluate()
torch.cuda.synchronize()
t0 = time.time()
for step in range(steps):
    i = np.random.randint(len(tr_img))
    img, alpha, info = render(tr_vm[i], min(step // 1000, 3))
    strategy.step_pre_backward(params, opt, state, step, info)
    gt = tr_img[i:i + 1]
    loss = 0.8 * F.l1_loss(img, gt) + 0.2 * (1 - ssim(img, gt))
    loss.backward()
    for o in opt.values():
        o.step()
        o.zero_grad(set_to_none=True)
    sched.step()
    strategy.step_post_backward(params, opt, state, step, info, packed=False)
    if eval_every and (step + 1) % eval_every == 0:
        report(step + 1)
    if (step + 1) % 1000 == 0:
        torch.cuda.synchronize()
        print(f'step {step + 1}: {1e3 * (time.time() - t0) / (step + 1):.2f} ms/step, {len(params["means"])} gaussians, loss {loss.item():.4f}', flush=True)
torch.cuda.synchronize()
dt = time.time() - t0
p1, s1 = evaluate(save=True)
print(f'gsplat DefaultStrategy {steps} steps: {dt:.1f} s ({1e3 * dt / steps:.2f} ms/step), {len(params["means"])} gaussians; '
      f'test PSNR {p0:.2f} -> {p1:.2f} dB, SSIM {s0:.3f} -> {s1:.3f}')
