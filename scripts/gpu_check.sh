#!/usr/bin/env bash
# The JAX backend on one GPU (issue 28): env-steps/s and PPO steps/s at 4096 envs, then the
# whole controller benchmark with --backend jax. For a machine that has an NVIDIA GPU; CI
# runs everything on CPU and never runs this script.
#
#   python3 -m venv venv && source venv/bin/activate
#   pip install torch==2.13.0 && pip install ".[rl,jax]" && pip install "jax[cuda12]"
#   bash scripts/gpu_check.sh [OUT]          # OUT: where the benchmark goes (gpu-check)
#
# What it prints, in order (about 10 minutes on one recent GPU, compilation included —
# an estimate: it has not been run on a GPU yet):
#   1. the device JAX sees (the script stops if it is not a GPU);
#   2. raw stepping of Orbit-v0 + EKF at 4096 envs on the GPU — the batch step (the resets only
#      where an episode ended), gymnax's auto-resetting step vmapped, and the noise given —
#      against the numpy native vector env on this machine's CPU (scripts/jax_stepping_speed.py);
#   3. PPO at the shipped recipe with 4096 envs (one seed; the minibatch size stays the
#      recipe's 1024) and with 16 envs, against stable-baselines3 on the CPU
#      (scripts/jax_training_speed.py);
#   4. fir-gym benchmark-controllers --backend jax: every plant and kind the JAX backend has,
#      5 seeds each in one program per plant and kind, the time of the whole run.
set -euo pipefail

out=${1:-gpu-check}
here=$(cd "$(dirname "$0")" && pwd)
export MUJOCO_GL="${MUJOCO_GL:-egl}"

echo "== 1. the device"
python - <<'PY'
import jax

devices = jax.devices()
print(f"jax {jax.__version__}: {devices}")
if devices[0].platform != "gpu":
    raise SystemExit("no GPU: JAX runs on " + devices[0].platform + " (install jax[cuda12])")
PY
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true

echo "== 2. stepping Orbit-v0 + EKF at 4096 envs"
python "$here/jax_stepping_speed.py" --envs 4096 --steps 200 --reps 3 \
  --numpy-batches 256 1024 4096 --modes batch_step step step_with_noise

echo "== 3. PPO: 4096 envs (JAX only), then 16 envs against stable-baselines3"
python "$here/jax_training_speed.py" --n-envs 4096 --steps 4194304 --skip-sb3
python "$here/jax_training_speed.py" --steps 65536 --seeds 5

echo "== 4. the controller benchmark, --backend jax"
start=$(date +%s)
fir-gym benchmark-controllers --backend jax --out "$out" --no-progress
echo "== benchmark-controllers --backend jax took $(( $(date +%s) - start )) s (compilation included)"
