#pragma once
/// @file Broken-invariant channel: aborts with file:line. Never used for bad input data, which
/// becomes a counted rejection instead (STYLE.md rule 4).

#include <cstdio>
#include <cstdlib>

#define TARMAC_ASSERT(cond, msg)                                                              \
  do {                                                                                        \
    if (!(cond)) {                                                                            \
      std::fprintf(stderr, "%s:%d: invariant violated: %s (%s)\n", __FILE__, __LINE__, #cond, \
                   msg);                                                                      \
      std::abort();                                                                           \
    }                                                                                         \
  } while (false)
