// FUZZ_CHECK for libFuzzer targets: a broken invariant prints what broke and
// aborts, which libFuzzer records as a crash with the input that caused it.
#ifndef TPR_TESTS_FUZZ_FUZZ_CHECK_H_
#define TPR_TESTS_FUZZ_FUZZ_CHECK_H_

#include <cstdio>
#include <cstdlib>
#include <initializer_list>

#include "absl/status/status.h"

#define FUZZ_CHECK(cond, what)                                             \
  do {                                                                     \
    if (!(cond)) {                                                         \
      std::fprintf(stderr, "%s:%d: invariant broken: %s (%s)\n", __FILE__, \
                   __LINE__, what, #cond);                                 \
      std::abort();                                                        \
    }                                                                      \
  } while (0)

namespace tpr::fuzz {

// CheckRefusal aborts unless `status` (not OK) has one of the `allowed`
// codes and a message saying why: what every target expects of bad input.
inline void CheckRefusal(const absl::Status& status,
                         std::initializer_list<absl::StatusCode> allowed) {
  bool known = false;
  for (absl::StatusCode code : allowed) known = known || status.code() == code;
  if (!known)
    std::fprintf(stderr, "refused with %s\n", status.ToString().c_str());
  FUZZ_CHECK(known, "a refusal has a documented status code");
  FUZZ_CHECK(!status.message().empty(), "a refusal says why");
}

}  // namespace tpr::fuzz

#endif  // TPR_TESTS_FUZZ_FUZZ_CHECK_H_
