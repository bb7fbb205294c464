#!/usr/bin/env bash
# ./fuzz.sh [SECONDS] [TARGET...]
#
# Builds the libFuzzer targets of fuzz/ with clang, ASan and UBSan in ./build-fuzz, writes the seed
# corpus (fuzz/seed_files.h, generated now: no mesh file is kept in git) and runs each target for
# SECONDS (default 30), one after the other. TARGET names (obj ply gltf glb xz, and the decoder
# and algorithm targets lossy_subgrid, quantized_mesh, pairing, cluster) restrict the run; default: every
# target built.
#
#   fuzz-out/seeds/<target>/    the generated seeds (rewritten each run)
#   fuzz-out/corpus/<target>/   the corpus libFuzzer grows (kept between runs: later runs resume)
#   fuzz-out/crashes/<target>/  crash-*, leak-*, timeout-*, oom-* inputs
#   fuzz-out/logs/<target>.log  the full libFuzzer output
#
# Reproduce a finding:  build-fuzz/fuzz/fuzz_<target> fuzz-out/crashes/<target>/crash-...
# Exit status: 0 if no target failed, 1 otherwise (every target still runs).
set -euo pipefail
cd "$(dirname "$0")"
SECS=${1:-30}
shift || true

CXX_FUZZ=""
for c in clang++-14 clang++; do
  if command -v "$c" >/dev/null 2>&1; then CXX_FUZZ=$c; break; fi
done
if [ -z "$CXX_FUZZ" ]; then
  echo "fuzz.sh: clang is missing (libFuzzer comes with it); installing Debian's clang"
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y clang
  CXX_FUZZ=clang++
fi
CC_FUZZ=${CXX_FUZZ/clang++/clang}

cmake -S . -B build-fuzz -DCMAKE_BUILD_TYPE=RelWithDebInfo -DSLIM_FUZZ=ON -DSLIM_SANITIZE=ON \
  -DCMAKE_C_COMPILER="$CC_FUZZ" -DCMAKE_CXX_COMPILER="$CXX_FUZZ" >/dev/null
cmake --build build-fuzz --target slimrt_fuzz -j"$(nproc)"

OUT=fuzz-out
rm -rf "$OUT/seeds"
build-fuzz/fuzz/make_seeds "$OUT/seeds"

targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  for f in build-fuzz/fuzz/fuzz_*; do
    [ -x "$f" ] && targets+=("${f##*/fuzz_}")
  done
fi

export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
failed=()
printf '%-16s %8s %10s %8s %8s  %s\n' target seconds execs corpus cov result
for t in "${targets[@]}"; do
  bin=build-fuzz/fuzz/fuzz_$t
  [ -x "$bin" ] || { echo "fuzz.sh: no target $bin"; failed+=("$t"); continue; }
  mkdir -p "$OUT/corpus/$t" "$OUT/crashes/$t" "$OUT/logs" "$OUT/seeds/$t"
  log=$OUT/logs/$t.log
  rc=0
  # -timeout: seconds per input before it counts as a hang; -rss_limit_mb: runaway allocations
  # (a header claiming 2^40 elements must be refused, not allocated) count as failures too.
  # Dictionaries (fuzz/dict/): tokens for deep nesting and numbers beyond their types.
  dict=()
  case $t in
    obj | ply | gltf) dict=(-dict="fuzz/dict/$t.dict") ;;
    glb) dict=(-dict=fuzz/dict/gltf.dict) ;;
  esac
  "$bin" "${dict[@]}" -max_total_time="$SECS" -timeout=10 -rss_limit_mb=2048 -max_len=16384 \
    -print_final_stats=1 -artifact_prefix="$OUT/crashes/$t/" \
    "$OUT/corpus/$t" "$OUT/seeds/$t" >"$log" 2>&1 || rc=$?
  execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo 0)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | grep -o '[0-9]*' || echo 0)
  corpus=$(find "$OUT/corpus/$t" -type f | wc -l)
  result=ok
  if [ $rc -ne 0 ]; then
    result="FAILED (exit $rc): $(ls -t "$OUT/crashes/$t" | head -1)"
    failed+=("$t")
    grep -m1 -E 'ERROR: (AddressSanitizer|libFuzzer|LeakSanitizer)|runtime error|slimrt fuzz check' \
      "$log" || true
  fi
  printf '%-16s %8s %10s %8s %8s  %s\n' "$t" "$SECS" "${execs:-0}" "$corpus" "${cov:-0}" "$result"
done
if [ ${#failed[@]} -ne 0 ]; then
  echo "fuzz.sh: failures in: ${failed[*]} (inputs in $OUT/crashes/, logs in $OUT/logs/)"
  exit 1
fi
echo "fuzz.sh: no failures"
