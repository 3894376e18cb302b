#!/usr/bin/env bash
# Runs on the GPU machine from the bundle scripts/gpu_bundle made (copied there as gpu_bundle/run.sh): the CUDA
# tests, compute-sanitizer memcheck and racecheck on them, and the renderer benchmark. Logs go to $OUT (or
# gpu_bundle/out). Exit 0: all passed; 1: a failure; 2: no usable CUDA device (nothing CUDA was checked).
set -uo pipefail
here=$(cd "$(dirname "$0")" && pwd)
out=${OUT:-$here/out}
mkdir -p "$out"
export LD_LIBRARY_PATH="$here/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
# A machine with an older glibc than the bundle needs: start the programs through the bundled loader.
need=$(cat "$here/glibc_needed" 2>/dev/null || echo 0)
have=$(getconf GNU_LIBC_VERSION 2>/dev/null | awk '{print $2}')
run=()
if [[ -n "${FORCE_BUNDLED_GLIBC:-}" || "$(printf '%s\n%s\n' "$need" "${have:-0}" | sort -V | head -1)" != "$need" ]]; then
  run=("$here/glibc/ld-linux-x86-64.so.2" --library-path "$here/glibc:$LD_LIBRARY_PATH")  # keeps the driver paths
  echo "glibc ${have:-unknown} < $need: using the bundled glibc"
fi
status=0
nvidia-smi --query-gpu=name,driver_version,memory.total,compute_cap --format=csv 2>&1 | tee "$out/device.txt"
echo "== CUDA tests (and the CPU executor) =="
"${run[@]}" "$here/bin/diffdope_cuda_tests" 2>&1 | tee "$out/tests.log"
[[ ${PIPESTATUS[0]} -eq 0 ]] || status=1
no_device=0
grep -q 'SKIPPED \] .*/Cuda' "$out/tests.log" && no_device=1
cs=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
if [[ $no_device -eq 0 && -x "$cs" ]]; then
  for tool in memcheck racecheck; do
    echo "== compute-sanitizer --tool $tool =="
    "$cs" --tool "$tool" --error-exitcode 3 "${run[@]}" "$here/bin/diffdope_cuda_tests" --gtest_filter='*/Cuda' \
      > "$out/sanitizer_$tool.log" 2>&1 || { echo "compute-sanitizer $tool failed"; status=1; }
    tail -4 "$out/sanitizer_$tool.log"
  done
fi
echo "== renderer benchmark (B = 32) =="
"${run[@]}" "$here/bin/bench_renderer" --benchmark_filter='Cuda|BM_ForwardGradient/640' --benchmark_min_time=0.5 \
  --benchmark_out="$out/bench.json" --benchmark_out_format=json 2>&1 | tee "$out/bench.txt" || status=1
if [[ $status -ne 0 ]]; then echo "gpu checks: FAILURES"; exit 1; fi
if [[ $no_device -eq 1 ]]; then echo "gpu checks: no usable CUDA device: nothing CUDA was checked"; exit 2; fi
echo "gpu checks: all passed"
