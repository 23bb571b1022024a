// FUZZ_CHECK for libFuzzer targets: a broken invariant prints what broke and
// aborts, which libFuzzer records as a crash with the input that caused it.
#ifndef TPR_TESTS_FUZZ_FUZZ_CHECK_H_
#define TPR_TESTS_FUZZ_FUZZ_CHECK_H_

#include <cstdio>
#include <cstdlib>

#define FUZZ_CHECK(cond, what)                                          \
  do {                                                                  \
    if (!(cond)) {                                                      \
      std::fprintf(stderr, "%s:%d: invariant broken: %s (%s)\n",        \
                   __FILE__, __LINE__, what, #cond);                    \
      std::abort();                                                     \
    }                                                                   \
  } while (0)

#endif  // TPR_TESTS_FUZZ_FUZZ_CHECK_H_
