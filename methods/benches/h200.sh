#!/bin/bash
# Issues 11, 12 and 14 measured on the lent H200 beside gsplat, as one device call (231 s on
# 2026-12-04, 263 s of device time with the machine's start; each part has its own time limit,
# most important first; the CPU sweep by thread count only with CPU=1). The SM clock is logged
# every 100 ms to $OUT/clocks.csv: it follows the load. Prepared here, run there
# from the repository root with carry [".gl", ".dev"]:
#   .gl/   the Vulkan loader debs (see the device README);
#   .dev/  `splat.xz` (cargo build --release -p splat-cli; strip; xz: 73 MB stripped, over
#          the 64 MiB a call carries), `gpu-bench.xz` (the executable `cargo bench -p
#          splat-methods --bench gpu --no-run` prints; strip; xz), `viewer-bench.xz` (the same
#          for `cargo bench -p splat-cli --bench viewer --no-run`), `raster-order.xz`
#          (`cargo build --release -p splat-gpu --example raster_order`; strip; xz),
#          shared/bench/{make_scene,gsplat_bench,gsplat_train}.py,
#          gsplat-1.5.3-py3-none-any.whl (pip download --no-deps) and `stilllife/`
#          (methods/benches/mitsuba_dataset.py .dev/stilllife).
# Everything is logged to $OUT/log.txt; the fit and tradeoff outputs come back as .tgz.
# DRY=1 runs the same steps small and without gsplat (no CUDA), to check the script here.
set -uo pipefail
OUT=${OUT:-/tmp/h200-out}
mkdir -p "$OUT"
exec > >(tee -a "$OUT/log.txt") 2>&1
if [ "${DRY:-0}" = 1 ]; then
    N=20000 W=320 H=180 ITERS=2 STEPS=20 N_TRADEOFF=5000 GSPLAT=0 SLOW=10
else
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
    export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    N=1000000 W=1920 H=1080 ITERS=20 STEPS=7000 N_TRADEOFF=200000 GSPLAT=1 SLOW=1
    nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.mem --format=csv
    nvidia-smi --query-gpu=timestamp,clocks.sm,power.draw,utilization.gpu --format=csv \
        -lms 100 >"$OUT/clocks.csv" &
    clock_log=$!
fi
part() { echo; echo "=== $1 ($(date +%T))"; }
# Each part's time limit, in seconds on the H200 (SLOW times that on lavapipe).
limit() { timeout $(($1 * SLOW)) "${@:2}"; }
mkdir -p /tmp/bin
for x in splat gpu-bench viewer-bench raster-order; do
    python3 -c 'import lzma, shutil, sys; shutil.copyfileobj(lzma.open(sys.argv[1]), open(sys.argv[2], "wb"))' \
        .dev/$x.xz /tmp/bin/$x && chmod +x /tmp/bin/$x
done
splat=/tmp/bin/splat
scene=/tmp/scene
mkdir -p "$scene"
python3 .dev/make_scene.py $N $W $H "$scene"
bench() { limit "$1" $splat bench --scene "$scene/scene.ply" --camera "$scene/camera.json" "${@:2}"; }

part "issue 11: our GPU frames, $N Gaussians at ${W}x$H"
bench 60 --backend gpu --iters $ITERS --raw-out "$scene/ours.f32"
part "issue 11: the same with naga's run-time checks in the shaders (what they cost)"
bench 60 --backend gpu --iters $ITERS --shader-checks

if [ $GSPLAT = 1 ]; then
    part "gsplat 1.5.3 on the same scene (compiles its CUDA code first)"
    python3 -m pip install -q --no-deps --target /tmp/site .dev/gsplat-*.whl
    export PYTHONPATH=/tmp/site TORCH_CUDA_ARCH_LIST=9.0 MAX_JOBS=12 PYTHONUNBUFFERED=1
    # gsplat_bench.py, then the peak memory torch allocated (the scene included).
    limit 150 python3 -c 'import runpy, sys, torch
sys.argv = sys.argv[1:]
runpy.run_path(sys.argv[0], run_name="__main__")
print(f"gsplat peak CUDA memory allocated: {torch.cuda.max_memory_allocated() / 2**20:.1f} MiB")' \
        .dev/gsplat_bench.py "$scene" $ITERS
fi

part "issue 59: splat view's frame latency and splat fit --view's cost, $N Gaussians at ${W}x$H on the GPU"
limit 90 env SPLAT=$splat /tmp/bin/viewer-bench gpu $N $W $H

# The comparison with gsplat 1.5.3's trainer as shared/bench/gsplat_train.py runs it: 100,000
# random points in a cube of half-side 1.5, each of size 0.02 and gray, scene scale 1.3
# (= 0.2618 x the cameras' extent, 4.97), and no opacity resets (gsplat 1.5.3's reset test
# never passes). No evaluations during the run, so the time per step is the loop's.
part "issue 12: splat fit, 3DGS on the GPU, stilllife (Mitsuba 3), $STEPS steps, as gsplat_train.py"
fit=/tmp/fit
limit 120 $splat fit .dev/stilllife --backend gpu --steps $STEPS --global-scale 0.2618 \
    --init-extent 1.1538 --init-size 0.02 --init-color 0.5,0.5,0.5 --no-opacity-reset \
    --eval-every 0 --checkpoint-every 0 --out $fit
tar czf "$OUT/fit.tgz" -C $fit --exclude scene.ply . 2>/dev/null
if [ $GSPLAT = 1 ]; then
    part "issue 12: gsplat DefaultStrategy on the same data (shared/bench/gsplat_train.py)"
    limit 80 python3 .dev/gsplat_train.py .dev/stilllife $STEPS
fi

part "issue 12: one training frame of the trained scene, ours and gsplat's, per stage"
trained=/tmp/trained
mkdir -p $trained
cp $fit/scene.ply $trained/ && python3 - .dev/stilllife $trained/camera.json <<'EOF'
import json, math, sys
import numpy as np
from PIL import Image
d = json.load(open(f'{sys.argv[1]}/transforms_test.json'))
frame = d['frames'][0]
w, h = Image.open(f"{sys.argv[1]}/{frame['file_path']}.png").size
w2c = np.linalg.inv(np.array(frame['transform_matrix']) @ np.diag([1.0, -1, -1, 1]))
f = 0.5 * w / math.tan(0.5 * d['camera_angle_x'])
json.dump({'width': w, 'height': h, 'fx': f, 'fy': f, 'cx': w / 2, 'cy': h / 2,
           'world_to_camera': w2c.tolist(), 'model': 'pinhole'}, open(sys.argv[2], 'w'))
EOF
limit 40 $splat bench --scene $trained/scene.ply --camera $trained/camera.json --backend gpu \
    --iters $ITERS --raw-out $trained/ours.f32
[ $GSPLAT = 1 ] && limit 40 python3 .dev/gsplat_bench.py $trained $ITERS

part "issue 11: the GPU backward blend by accumulation, one-shot against resident"
limit 45 /tmp/bin/gpu-bench $((N / 5)) $W $H

part "issue 14: splat tradeoff on the GPU, $N_TRADEOFF Gaussians at 960x540"
big=/tmp/big
mkdir -p $big
python3 .dev/make_scene.py $N_TRADEOFF 960 540 $big
limit 100 $splat tradeoff --backend gpu --scene $big/scene.ply --camera $big/camera.json \
    --iters 5 --out /tmp/tradeoff
tar czf "$OUT/tradeoff.tgz" -C /tmp/tradeoff . 2>/dev/null

part "issue 63: programmable blending (which extensions; the order test and its time)"
limit 20 /tmp/bin/raster-order 1920 1080 64 3 || echo "raster-order exited $?"

if [ "${CPU:-0}" = 1 ]; then
    part "issue 11: the CPU backend by thread count"
    bench 80 --backend cpu --iters 2 --threads 1,2,4,8,16
fi

part "done"
[ -n "${clock_log:-}" ] && kill "$clock_log"
ls -la "$OUT"
