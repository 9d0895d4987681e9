"""A 360-degree Blender-format dataset path-traced by Mitsuba 3 (independent of this project's
renderers), for comparing `splat fit` with gsplat's trainer on the same data.

Usage: mitsuba_dataset.py OUT [VIEWS=100] [SIZE=200] [SPP=256]   (pip install mitsuba numpy)

The scene ("still life"): a checker-textured cube, a rough red plastic sphere, a rough gold
cylinder and a ring of eight small diffuse spheres in eight colors, lit by a constant
environment and two spherical lights, all inside radius 1.4. Cameras lie on a Fibonacci
spiral over the sphere of radius 4 (elevations -37 to +72 degrees) looking at the origin;
every 5th view is held out (`transforms_test.json`). Images are RGBA PNG, straight alpha,
the object on a transparent background (emitters hidden from camera rays).
"""
import json, math, os, sys

import mitsuba as mi
import numpy as np

mi.set_variant('scalar_rgb')
out = sys.argv[1]
views = int(sys.argv[2]) if len(sys.argv) > 2 else 100
size = int(sys.argv[3]) if len(sys.argv) > 3 else 200
spp = int(sys.argv[4]) if len(sys.argv) > 4 else 256
fov_x = 40.0
radius = 4.0
T = mi.ScalarTransform4f


def diffuse(rgb):
    return {'type': 'diffuse', 'reflectance': {'type': 'rgb', 'value': rgb}}


scene = {
    'type': 'scene',
    'integrator': {'type': 'path', 'max_depth': 6, 'hide_emitters': True},
    'env': {'type': 'constant', 'radiance': {'type': 'rgb', 'value': 0.35}},
    'key': {'type': 'sphere', 'center': [3.0, 4.0, 3.0], 'radius': 0.5,
            'emitter': {'type': 'area', 'radiance': {'type': 'rgb', 'value': [9.0, 8.5, 8.0]}}},
    'fill': {'type': 'sphere', 'center': [-4.0, -2.0, 2.5], 'radius': 0.5,
             'emitter': {'type': 'area', 'radiance': {'type': 'rgb', 'value': [2.0, 2.5, 3.5]}}},
    'cube': {'type': 'cube', 'to_world': T().translate([-0.45, -0.2, -0.3]).rotate([0.3, 1, 0.2], 35).scale(0.45),
             'bsdf': {'type': 'diffuse', 'reflectance': {
                 'type': 'checkerboard', 'color0': {'type': 'rgb', 'value': [0.9, 0.85, 0.7]},
                 'color1': {'type': 'rgb', 'value': [0.1, 0.25, 0.55]},
                 'to_uv': mi.ScalarTransform3f().scale([4.0, 4.0])}}},
    'ball': {'type': 'sphere', 'center': [0.55, 0.35, 0.2], 'radius': 0.45,
             'bsdf': {'type': 'roughplastic', 'alpha': 0.15,
                      'diffuse_reflectance': {'type': 'rgb', 'value': [0.7, 0.08, 0.05]}}},
    'can': {'type': 'cylinder', 'p0': [0.3, -0.6, -0.9], 'p1': [0.3, -0.6, 0.5], 'radius': 0.25,
            'bsdf': {'type': 'roughconductor', 'material': 'Au', 'alpha': 0.25}},
    'can_lid': {'type': 'disk', 'to_world': T().translate([0.3, -0.6, 0.5]).scale(0.25),
                'bsdf': {'type': 'roughconductor', 'material': 'Au', 'alpha': 0.25}},
}
colors = [[0.9, 0.9, 0.9], [0.9, 0.6, 0.1], [0.2, 0.7, 0.2], [0.1, 0.6, 0.8],
          [0.5, 0.2, 0.7], [0.9, 0.3, 0.5], [0.6, 0.5, 0.3], [0.15, 0.15, 0.15]]
for k, rgb in enumerate(colors):
    a = 2 * math.pi * k / len(colors)
    scene[f'bead{k}'] = {'type': 'sphere', 'center': [1.15 * math.cos(a), 1.15 * math.sin(a), -0.1 + 0.25 * math.sin(3 * a)],
                         'radius': 0.13, 'bsdf': diffuse(rgb)}
scene = mi.load_dict(scene)


def camera_to_world(eye):
    """OpenGL camera axes (x right, y up, looking down -z), the Blender format's convention."""
    z = eye / np.linalg.norm(eye)
    up = np.array([0.0, 0.0, 1.0])
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, eye
    return m


golden = math.pi * (3 - math.sqrt(5))
frames = {'train': [], 'test': []}
for i in range(views):
    zc = 0.95 - 1.55 * (i + 0.5) / views  # sin(elevation) from 0.95 down to -0.6
    ring = math.sqrt(1 - zc * zc)
    eye = radius * np.array([ring * math.cos(golden * i), ring * math.sin(golden * i), zc])
    c2w = camera_to_world(eye)
    sensor = mi.load_dict({
        'type': 'perspective', 'fov': fov_x, 'fov_axis': 'x',
        # Mitsuba's camera looks down +z with +x to the left: the OpenGL frame turned half
        # a revolution about y.
        'to_world': mi.ScalarTransform4f(c2w @ np.diag([-1.0, 1.0, -1.0, 1.0])),
        'film': {'type': 'hdrfilm', 'width': size, 'height': size, 'pixel_format': 'rgba',
                 'rfilter': {'type': 'box'}},
        'sampler': {'type': 'independent', 'sample_count': spp, 'seed': i}})
    img = np.array(mi.render(scene, sensor=sensor, seed=i))
    rgb, alpha = img[..., :3], np.clip(img[..., 3:4], 0, 1)
    rgb = np.where(alpha > 0, rgb / np.maximum(alpha, 1e-6), 0)  # straight alpha
    split = 'test' if i % 5 == 4 else 'train'
    name = f'{split}/r_{len(frames[split])}'
    os.makedirs(f'{out}/{split}', exist_ok=True)
    rgba = mi.Bitmap(np.concatenate([rgb, alpha], -1).astype(np.float32), mi.Bitmap.PixelFormat.RGBA)
    rgba.convert(mi.Bitmap.PixelFormat.RGBA, mi.Struct.Type.UInt8, srgb_gamma=True).write(f'{out}/{name}.png')
    frames[split].append({'file_path': f'./{name}', 'transform_matrix': c2w.tolist()})
    print(f'\r{i + 1}/{views} views', end='', flush=True)
print()
for split, fr in frames.items():
    with open(f'{out}/transforms_{split}.json', 'w') as f:
        json.dump({'camera_angle_x': math.radians(fov_x), 'frames': fr}, f, indent=1)
