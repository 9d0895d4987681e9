#!/bin/bash
# Issue 61 measured on the lent machine, as one device call: `splat fit` under OpenMPI's
# mpirun, CPU ranks N = 1, 2, 4, 8 on its 16 cores (threads split among them; data parallel,
# and from 2 ranks on sharded too), and
# on the GPU two ranks sharing it against one process at the same batch (what the exchange
# costs: each step's sum down, gathered through shared memory, the total up), and sharded
# GPU ranks (1 and 2: the records' trip through the host). Prepared here,
# run there from the repository root with carry [".gl", ".dev"]:
#   .gl/        the Vulkan loader debs (see the device README);
#   .dev/       `splat-mpi.xz` (cargo build --release -p splat-cli --features mpi; strip; xz),
#               `stilllife/` (methods/benches/mitsuba_dataset.py .dev/stilllife), and
#   .dev/mpi/   OpenMPI's debs and those it needs beyond a base system (Debian 12):
#               apt-get download libopenmpi3 openmpi-bin openmpi-common libevent-core-2.1-7
#               libevent-pthreads-2.1-7 libfabric1 libhwloc15 libibverbs1 libnl-3-200
#               libnl-route-3-200 libpmix2 libpsm-infinipath1 libpsm2-2 libucx0 librdmacm1
#               libnuma1 libmunge2 libatomic1 libpciaccess0 libxnvctrl0 ocl-icd-libopencl1
#               libxml2 libicu72 libx11-6 libxcb1 libxau6 libxdmcp6 libbsd0 libmd0 (17 MB),
#               unpacked under /tmp/mpiroot (not /: the device README warns other packages
#               can break it) and found there through OPAL_PREFIX and LD_LIBRARY_PATH.
# Everything is logged to $OUT/log.txt. DRY=1 runs the same steps small with this machine's
# mpirun and the debug build, to check the script here.
set -uo pipefail
OUT=${OUT:-/tmp/h200-mpi-out}
mkdir -p "$OUT"
exec > >(tee -a "$OUT/log.txt") 2>&1
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
if [ "${DRY:-0}" = 1 ]; then
    STEPS=40 GPU_STEPS=20 CORES=2 RANKS="1 2" SLOW=10 splat=target/debug/splat
    data=${DATA:-/tmp/mitsuba}
else
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
    export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    for f in .dev/mpi/*.deb; do dpkg -x "$f" /tmp/mpiroot; done
    R=/tmp/mpiroot/usr
    export OPAL_PREFIX=$R OPAL_LIBDIR=$R/lib/x86_64-linux-gnu/openmpi/lib PATH=$R/bin:$PATH \
        LD_LIBRARY_PATH=$R/lib/x86_64-linux-gnu/openmpi/lib:$R/lib/x86_64-linux-gnu
    ln -sf orterun $R/bin/mpirun
    STEPS=800 GPU_STEPS=2000 CORES=16 RANKS="1 2 4 8" SLOW=1 splat=/tmp/bin/splat
    data=.dev/stilllife
    mkdir -p /tmp/bin
    python3 -c 'import lzma, shutil, sys; shutil.copyfileobj(lzma.open(sys.argv[1]), open(sys.argv[2], "wb"))' \
        .dev/splat-mpi.xz $splat && chmod +x $splat
    nvidia-smi --query-gpu=name,driver_version --format=csv
fi
part() { echo; echo "=== $1 ($(date +%T))"; }
limit() { timeout $(($1 * SLOW)) "${@:2}"; }
# The still life as gsplat_train.py trains it (docs/cli.md), without evaluations.
still=(--global-scale 0.2618 --init-extent 1.1538 --init-size 0.02 --init-color 0.5,0.5,0.5
    --no-opacity-reset --eval-every 0 --checkpoint-every 0)
mpirun --version | head -1

part "CPU ranks: $STEPS views in batches of 8, $CORES cores split among the ranks"
for n in $RANKS; do
    echo "--- $n ranks, $((CORES / n)) threads each"
    limit 90 mpirun --oversubscribe --bind-to none -n $n -x RAYON_NUM_THREADS=$((CORES / n)) \
        $splat fit "$data" "${still[@]}" --backend cpu --steps $STEPS --batch 8 --out /tmp/cpu$n \
        | grep -E "steps|sent|\| (exchange|step) "
    [ $n -gt 1 ] || continue
    echo "--- $n ranks, $((CORES / n)) threads each, --sharded"
    limit 90 mpirun --oversubscribe --bind-to none -n $n -x RAYON_NUM_THREADS=$((CORES / n)) \
        $splat fit "$data" "${still[@]}" --backend cpu --steps $STEPS --batch 8 --sharded \
        --out /tmp/sharded$n | grep -E "steps|sent|peak|\| (exchange|step) "
done

part "GPU: $GPU_STEPS views in batches of 2, one process against two ranks on the one GPU"
limit 60 $splat fit "$data" "${still[@]}" --backend gpu --steps $GPU_STEPS --batch 2 \
    --out /tmp/gpu1 | grep -E "steps|\| (exchange|optimizer|step) "
limit 90 mpirun --oversubscribe -n 2 $splat fit "$data" "${still[@]}" --backend gpu \
    --steps $GPU_STEPS --batch 2 --out /tmp/gpu2 | grep -E "steps|sent|\| (exchange|optimizer|step) "
# Sharded: one rank (what the records' trip through the host costs against the loop above),
# then two ranks sharing the GPU.
for n in 1 2; do
    echo "--- $n ranks, --sharded"
    limit 90 mpirun --oversubscribe -n $n $splat fit "$data" "${still[@]}" --backend gpu \
        --steps $GPU_STEPS --batch 2 --sharded --out /tmp/gpu-sharded$n \
        | grep -E "steps|sent|peak|\| (preprocess|project adjoint|exchange|optimizer|step) "
done

part "done"
