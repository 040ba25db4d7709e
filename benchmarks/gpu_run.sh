#!/usr/bin/env bash
# The GPU parts of the learned planner in one run on the device machine
# (docs/policy.md, "Training shapes from a file"): the environment's throughput
# on the GPU, then the full-scale il_rl_gpu training (benchmarks/configs/il_rl_gpu.toml),
# both into $OUT.
#
# Here, once, in the repository root (the device image lacks trimesh and
# manifold3d, and the real shapes' packages):
#   echo /.whl/ >> .git/info/exclude
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 \
#     --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 \
#     --platform manylinux_2_17_x86_64 -d .whl trimesh==5.2.0 manifold3d==3.5.4
#   slicerecon train --config benchmarks/configs/il_rl_gpu.toml --write-pool .whl/pool_il_rl_gpu.npz
# There (carry .whl; TRAIN_SECONDS bounds the training, which checkpoints and
# resumes with RESUME=1):
#   bash benchmarks/gpu_run.sh
set -euo pipefail
OUT=${OUT:-runs/gpu}
DEVICE=${DEVICE:-cuda}
TRAIN_SECONDS=${TRAIN_SECONDS:-420}
mkdir -p "$OUT"
if ! python3 -c "import trimesh, manifold3d" 2>/dev/null; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl
  export PYTHONPATH=/tmp/site${PYTHONPATH:+:$PYTHONPATH}
fi
export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH} PYTHONUNBUFFERED=1
slicerecon() { python3 -c 'import sys; from slicerecon.cli import main; sys.exit(main())' "$@"; }
python3 benchmarks/env_throughput.py --surfaces surrogate --batches 256,1024 --seconds 5 \
  --out "$OUT/env_throughput_gpu.md"
resume=()
if [ "${RESUME:-0}" = 1 ]; then resume=(--resume); fi
status=0
timeout "$TRAIN_SECONDS" bash -c "$(declare -f slicerecon); slicerecon train --config benchmarks/configs/il_rl_gpu.toml \
  --device $DEVICE --pool .whl/pool_il_rl_gpu.npz --out $OUT/il_rl_gpu ${resume[*]:-}" \
  || status=$?
echo "training exit status $status (124: stopped at TRAIN_SECONDS, resume with RESUME=1)"
