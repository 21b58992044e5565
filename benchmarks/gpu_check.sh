#!/usr/bin/env bash
# The GPU check: run from the repository root on a machine with an NVIDIA GPU, whenever one is lent.
#
# It installs the project into .venv (an existing one is reused), prints the GPU's facts, and takes
# the figures of the device-resident frame at 1080p and 4K on cuda (benchmarks/gpu_check.py frame:
# the whole per-frame path, SenaFrameCompositor.composite_yuv; both passes' launches alone, also as
# one captured CUDA graph; the per-frame transfers; the largest difference from the CPU's planes),
# NVDEC's decoding rate against FFmpeg's software decoder, the CUDA tests (the kernels' [cuda] cases,
# parametrized by tests/test_kernels_maps.py's DEVICES; every module's CUDA compile is checked by the
# CPU suite, tests/test_kernels_cuda.py), and `sena-warp bench` at 1080p on cuda (`sena-warp video` end to end: NVENC when it opens, else
# libx264 on the host, said below; the transcode baseline). The most wanted figures come first.
# Every step has its own timeout and the whole check ends within BUDGET_S (5 minutes); a step that
# runs out of time is reported and the next one still runs while time is left.
#
# Figures: $OUT (default ./gpu_check_out): gpu_check.json (every step's figures), summary.txt, and
# each step's log. Environment: OUT, DATA (the shared data set holding pairs/rew_lawn_2160,
# default ../shared/data), CLIP_S (clip length, default 3 s), PY (a Python that imports the project
# and its dependencies already, e.g. where nothing can be downloaded: no .venv is made then).
#
# Exit status:
#   0  a CUDA GPU, its tests passed and every figure was taken
#   1  the CUDA tests failed (or ran out of time); the figures are taken all the same
#   2  the project could not be installed: nothing measured
#   3  no NVIDIA GPU: CUDA unmeasured (the tests' CUDA cases skip; the 1080p frame figures are taken
#      on the CPU so that every step runs, and are not CUDA figures)
#   4  a CUDA GPU, its tests passed, but a figure is missing (a step failed or ran out of time)

set -u
BUDGET_S=300
START=$SECONDS
OUT=${OUT:-./gpu_check_out}
DATA=${DATA:-../shared/data}
CLIP_S=${CLIP_S:-3}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
rm -f "$OUT"/*.json "$OUT"/*.log "$OUT/summary.txt"  # an earlier check's figures (its clips in work/ are reused)
PY=${PY:-}

# run NAME CAP_S COMMAND...: COMMAND with a timeout of CAP_S or the time left, whichever is less;
# its output goes to the terminal and to $OUT/NAME.log. Returns the command's status (124: timeout).
run() {
  local name=$1 cap=$2 left=$((BUDGET_S - (SECONDS - START)))
  shift 2
  ((left < cap)) && cap=$left
  if ((cap < 5)); then
    echo "== $name: not run, no time left of the ${BUDGET_S} s" | tee "$OUT/$name.log"
    return 124
  fi
  echo "== $name (at most $cap s)"
  timeout --kill-after=5 "$cap" "$@" 2>&1 | tee "$OUT/$name.log"
  local rc=${PIPESTATUS[0]}
  ((rc == 124 || rc == 137)) && echo "== $name: ran out of time ($cap s)"
  return "$rc"
}

if [[ -z $PY ]]; then
  PY=.venv/bin/python
  if [[ ! -x $PY ]]; then
    run venv 20 python3 -m venv .venv || { echo "gpu_check: cannot create .venv"; exit 2; }
  fi
  run install 120 .venv/bin/pip install -q -e ".[test]" || { echo "gpu_check: cannot install the project"; exit 2; }
fi
$PY -c "import sena_warp.video.stitch" || { echo "gpu_check: $PY cannot import the project"; exit 2; }

if command -v nvidia-smi >/dev/null; then
  run nvidia_smi 10 nvidia-smi --query-gpu=name,driver_version,memory.total,compute_cap,clocks.max.sm \
    --format=csv
else
  echo "== nvidia-smi: not found"
fi
run facts 20 $PY benchmarks/gpu_check.py facts "$OUT"
if [[ -f $OUT/facts.json ]]; then
  GPUS=$($PY -c "import json; print(json.load(open('$OUT/facts.json'))['cuda_devices'])")
  $PY - "$OUT/facts.json" <<'EOF'
import json, sys
facts = json.load(open(sys.argv[1]))
if not facts["nvenc_opens"]:
    print(f"NVENC: none here ({facts['nvenc_note']}): `sena-warp video` encodes with libx264 on the host")
print(f"NVDEC: {facts['nvdec_decodes']}; `sena-warp video` decodes on the host either way (its reader has no "
      f"NVDEC path; the nvdec step times NVDEC's decoding alone)")
EOF
else  # Warp's own count is missing: count what the driver lists
  GPUS=$(nvidia-smi -L 2>/dev/null | grep -c "^GPU")
fi
[[ -f $DATA/pairs/rew_lawn_2160/a.jpg ]] || echo "gpu_check: no benchmark pair at $DATA/pairs/rew_lawn_2160" \
  "(set DATA to the shared data set): the figure steps will fail"

# The CUDA cases of the kernel tests ([cuda] in their ids) and the device choice's own tests.
CUDA_TESTS=(tests/test_kernels_maps.py tests/test_kernels_remap.py tests/test_composite.py
  tests/test_kernels_frame_seam.py tests/test_kernels_runtime.py)
if ((GPUS == 0)); then
  echo "no NVIDIA GPU: CUDA unmeasured (Warp sees no CUDA device; the CUDA tests skip;" \
    "the 1080p frame figures below are the CPU's)"
  run frame_1080p 120 $PY benchmarks/gpu_check.py frame 1080p cpu "$CLIP_S" "$DATA" "$OUT"
  run cuda_tests 90 $PY -m pytest -q -rs -k "cuda or resolve_device" "${CUDA_TESTS[@]}"
  TESTS_RC=$?
  run summary 10 $PY benchmarks/gpu_check.py summary "$OUT"
  ((TESTS_RC != 0)) && { echo "gpu_check: the tests failed (exit $TESTS_RC)"; exit 1; }
  echo "no NVIDIA GPU: CUDA unmeasured"
  exit 3
fi

FIGURES_RC=0
run frame_1080p 45 $PY benchmarks/gpu_check.py frame 1080p cuda "$CLIP_S" "$DATA" "$OUT" || FIGURES_RC=1
run frame_4k 70 $PY benchmarks/gpu_check.py frame 4k cuda "$CLIP_S" "$DATA" "$OUT" || FIGURES_RC=1
run nvdec_1080p 20 $PY benchmarks/gpu_check.py nvdec 1080p "$CLIP_S" "$DATA" "$OUT" || FIGURES_RC=1
run cuda_tests 60 $PY -m pytest -q -rs -k "cuda or resolve_device" "${CUDA_TESTS[@]}"
TESTS_RC=$?
run bench_1080p 60 $PY benchmarks/gpu_check.py bench 1080p cuda "$CLIP_S" "$DATA" "$OUT" || FIGURES_RC=1
run summary 10 $PY benchmarks/gpu_check.py summary "$OUT"
echo "gpu_check: $((SECONDS - START)) s; figures in $OUT/gpu_check.json and $OUT/summary.txt"
((TESTS_RC != 0)) && { echo "gpu_check: the CUDA tests failed (exit $TESTS_RC)"; exit 1; }
((FIGURES_RC != 0)) && { echo "gpu_check: a figure is missing (see the step logs)"; exit 4; }
exit 0
