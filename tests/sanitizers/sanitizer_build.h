// What a test may know about the sanitizer it was compiled with
// (cmake/TprSanitize.cmake, scripts/test --sanitize), from the compilers'
// own macros: GCC defines __SANITIZE_ADDRESS__ / __SANITIZE_THREAD__, clang
// answers __has_feature. UBSan alone defines nothing; our builds pair it
// with ASan (-DTPR_SANITIZE=address,undefined), which is detected.
//
//   if (tpr::testing::kAddressSanitizer) GTEST_SKIP() << "why";
//   options.timeout_ms = 400 * tpr::testing::kSanitizerSlowdown;
#ifndef TPR_TESTS_SANITIZERS_SANITIZER_BUILD_H_
#define TPR_TESTS_SANITIZERS_SANITIZER_BUILD_H_

namespace tpr::testing {

#if defined(__SANITIZE_ADDRESS__)
inline constexpr bool kAddressSanitizer = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
inline constexpr bool kAddressSanitizer = true;
#else
inline constexpr bool kAddressSanitizer = false;
#endif
#else
inline constexpr bool kAddressSanitizer = false;
#endif

#if defined(__SANITIZE_THREAD__)
inline constexpr bool kThreadSanitizer = true;
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
inline constexpr bool kThreadSanitizer = true;
#else
inline constexpr bool kThreadSanitizer = false;
#endif
#else
inline constexpr bool kThreadSanitizer = false;
#endif

// kSanitizerSlowdown: the factor by which a test that waits on wall-clock
// time (an idle timeout, a call deadline, "promptly") scales its waits and
// bounds in a sanitized build, and 1 otherwise, so that a Release build
// asserts exactly what it did before. ASan and TSan slow our code 2-5x
// (more on a loaded 2-core machine); 5 keeps the margins those tests had
// in Release. It never scales a count or a memory bound.
inline constexpr int kSanitizerSlowdown =
    (kAddressSanitizer || kThreadSanitizer) ? 5 : 1;

}  // namespace tpr::testing

#endif  // TPR_TESTS_SANITIZERS_SANITIZER_BUILD_H_
