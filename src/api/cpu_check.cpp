// check_cpu_isa(): compiled without the SIMD flags of the rest of the library (CMakeLists.txt), so
// that it runs on any x86-64 CPU and reports a missing instruction set instead of the first
// AVX-512 or AVX2 instruction killing the process.
#include "slimrt/error.h"
#include "slimrt/scene.h"

#include <string>

#include "api/scene_impl.h"

#if defined(__x86_64__) || defined(__i386__)
#include <cpuid.h>
#endif

namespace slim {

void check_cpu_isa() {
#if defined(__x86_64__) || defined(__i386__)
  static const std::string missing = [] {
    __builtin_cpu_init();
    std::string m;
    auto need = [&](bool ok, const char* name) {
      if (!ok) m += std::string(m.empty() ? "" : ", ") + name;
    };
#if defined(SLIM_ISA_AVX2)
    need(__builtin_cpu_supports("avx2"), "avx2");
    need(__builtin_cpu_supports("fma"), "fma");
    need(__builtin_cpu_supports("bmi"), "bmi");
    need(__builtin_cpu_supports("bmi2"), "bmi2");
    // F16C from CPUID leaf 1 (ECX bit 29): clang 14's __builtin_cpu_supports has no "f16c".
    unsigned a = 0, b = 0, c = 0, d = 0;
    need(__get_cpuid(1, &a, &b, &c, &d) && (c & bit_F16C), "f16c");
#endif
#if defined(SLIM_ISA_AVX512)
    need(__builtin_cpu_supports("avx512f"), "avx512f");
    need(__builtin_cpu_supports("avx512vl"), "avx512vl");
    need(__builtin_cpu_supports("avx512bw"), "avx512bw");
    need(__builtin_cpu_supports("avx512dq"), "avx512dq");
#endif
    return m;
  }();
  if (!missing.empty())
    throw Error(std::string("slimrt was compiled for ") + simd_isa() +
                " (CMake SLIM_ISA) but this CPU lacks " + missing +
                ": rebuild with -DSLIM_ISA=avx2 (or auto, or scalar)");
#endif
}

bool cpu_has_isa(const std::string& isa) {
  if (isa == "scalar") return true;
#if defined(__x86_64__) || defined(__i386__)
  __builtin_cpu_init();
  unsigned a = 0, b = 0, c = 0, d = 0;
  const bool f16c = __get_cpuid(1, &a, &b, &c, &d) && (c & bit_F16C);
  const bool avx2 = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") &&
                    __builtin_cpu_supports("bmi") && __builtin_cpu_supports("bmi2") && f16c;
  if (isa == "avx2") return avx2;
  if (isa == "avx512")
    return avx2 && __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
           __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512dq");
#endif
  return false;
}

}  // namespace slim
