// SLIM_ASSERT: checks programming mistakes in debug builds (never untrusted input: that throws
// slim::Error).
#pragma once

#include <cstdio>
#include <cstdlib>

#ifdef NDEBUG
#define SLIM_ASSERT(cond) ((void)0)
#else
#define SLIM_ASSERT(cond)                                                              \
  ((cond) ? (void)0                                                                    \
          : (std::fprintf(stderr, "%s:%d: assertion failed: %s\n", __FILE__, __LINE__, \
                          #cond),                                                      \
             std::abort()))
#endif
