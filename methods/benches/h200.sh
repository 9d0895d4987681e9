#!/bin/bash
# Issue 11's measurement on the lent H200, as one device call (about 4 minutes, most of it
# gsplat compiling its CUDA code). Prepared here, run there from the repository root with
# carry [".gl", ".dev"]:
#   .gl/   the Vulkan loader debs (see the device README);
#   .dev/  `splat` (cargo build --release -p splat-cli; strip), shared/bench/{make_scene,
#          gsplat_bench}.py, and gsplat-1.5.3-py3-none-any.whl (pip download --no-deps).
# Writes ours_gpu.txt, ours_cpu.txt and gsplat.txt under $OUT.
set -uo pipefail
for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
scene=/tmp/scene
mkdir -p "$scene"
python3 .dev/make_scene.py 1000000 1920 1080 "$scene"
bench() { .dev/splat bench --scene "$scene/scene.ply" --camera "$scene/camera.json" "$@"; }
bench --backend gpu --iters 50 --raw-out "$scene/ours.f32" 2>&1 | tee "$OUT/ours_gpu.txt"
bench --backend cpu --iters 3 --threads 1,2,4,8,16 2>&1 | tee "$OUT/ours_cpu.txt"
python3 -m pip install -q --no-deps --target /tmp/site .dev/gsplat-*.whl
export PYTHONPATH=/tmp/site TORCH_CUDA_ARCH_LIST=9.0 MAX_JOBS=12 PYTHONUNBUFFERED=1
python3 .dev/gsplat_bench.py "$scene" 50 2>&1 | tee "$OUT/gsplat.txt"
