#!/usr/bin/env bash
# Installs what is missing (Debian 12, as root), builds and runs the whole test suite: ctest, then
# the Python module's tests with Debian's /usr/bin/python3 -m pytest (python/tests; a test that
# cannot run is reported as skipped with its reason).
#   ./test.sh              Release build in ./build
#   ./test.sh --sanitize   AddressSanitizer + UndefinedBehaviorSanitizer build in ./build-asan
#   ./test.sh --tsan       ThreadSanitizer build in ./build-tsan, the tests that start threads
#                          (TSAN_TESTS: a ctest -R regex instead of the list below)
# Extra arguments after the mode go to ctest (e.g. -R Robust).
set -euo pipefail
cd "$(dirname "$0")"
mode=release
case "${1:-}" in
  --sanitize) mode=asan; shift ;;
  --tsan) mode=tsan; shift ;;
esac
./scripts/setup.sh
case $mode in
  release)
    ./scripts/build.sh
    (cd build && ctest --output-on-failure -j"$(nproc)" "$@")
    PYTHONPATH="$PWD/build/python" /usr/bin/python3 -m pytest python/tests -rs -q
    ;;
  asan)
    # -O1 -g1: instrumented -O2 -g builds take ~10 min per large file on 2 cores; asserts stay on.
    BUILD_DIR=build-asan ./scripts/build.sh -DCMAKE_BUILD_TYPE=RelWithDebInfo \
      -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" -DSLIM_SANITIZE=ON -DSLIM_PYTHON=OFF
    export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:strict_string_checks=1
    export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
    cd build-asan && ctest --output-on-failure -j"$(nproc)" "$@"
    ;;
  tsan)
    BUILD_DIR=build-tsan ./scripts/build.sh -DCMAKE_BUILD_TYPE=RelWithDebInfo \
      -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" -DSLIM_TSAN=ON -DSLIM_PYTHON=OFF
    export TSAN_OPTIONS=halt_on_error=1:second_deadlock_stack=1
    # Debian's libtbb is not built with TSan: TSan cannot see the synchronisation inside it and
    # reports TBB's task bookkeeping and every lambda a task runs as races. So inside
    # slimrt_tests TBB runs its tasks on the calling thread (tests/test_robust_concurrency.cpp),
    # and the races TSan can find are between std::threads: RobustConcurrency's queries of one
    # scene from eight threads and two scenes built at once (the only tests that start threads
    # of their own); the tests that run the CLI (where TBB runs in parallel) are left out.
    tsan_tests='^RobustConcurrency\.'
    cd build-tsan && ctest --output-on-failure -j"$(nproc)" -R "${TSAN_TESTS:-$tsan_tests}" "$@"
    ;;
esac
