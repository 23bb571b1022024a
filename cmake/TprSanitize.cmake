# Sanitizer and fuzzing builds. Each goes in its own build directory:
#
#   cmake -S . -B build-asan -G Ninja -DTPR_SANITIZE=address,undefined
#   cmake -S . -B build-tsan -G Ninja -DTPR_SANITIZE=thread
#   CXX=clang++ cmake -S . -B build-fuzz -G Ninja -DTPR_FUZZ=ON
#
# TPR_SANITIZE instruments every target of ours (the Debian libraries are not
# instrumented: ASan still sees their heap through its malloc; TSan may report
# races inside them, hence tests/sanitizers/tsan.supp). Under thread, the
# indexer's own locks become standard-library ones (TPR_SYNC_STD,
# common/mutex.h). UBSan findings abort (-fno-sanitize-recover), so a test
# that trips one fails.
#
# TPR_FUZZ builds the libFuzzer targets of tests/fuzz/ (clang only): our code
# gets -fsanitize=fuzzer-no-link (coverage) plus ASan and UBSan unless
# TPR_SANITIZE names others; each target links -fsanitize=fuzzer.
include_guard(GLOBAL)

set(TPR_SANITIZE "" CACHE STRING
    "Sanitizers for every target: address,undefined | thread | empty (none)")
option(TPR_FUZZ "Build the libFuzzer targets of tests/fuzz (clang only)" OFF)

if(TPR_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID MATCHES "Clang")
    message(FATAL_ERROR "TPR_FUZZ needs clang (libFuzzer): CXX=clang++ cmake -DTPR_FUZZ=ON ...")
  endif()
  if(TPR_SANITIZE STREQUAL "")
    set(TPR_SANITIZE "address,undefined" CACHE STRING "" FORCE)
  endif()
  add_compile_options(-fsanitize=fuzzer-no-link)
  # Fuzz builds compile with clang, whose warning set differs from g++'s (the
  # compiler the strict build uses): keep the warnings, drop -Werror.
  list(REMOVE_ITEM TPR_WARNINGS -Werror)
endif()

if(NOT TPR_SANITIZE STREQUAL "")
  if(TPR_SANITIZE MATCHES "thread" AND TPR_SANITIZE MATCHES "address")
    message(FATAL_ERROR "TPR_SANITIZE: thread cannot be combined with address")
  endif()
  set(_tpr_san_flags -fsanitize=${TPR_SANITIZE} -fno-omit-frame-pointer -g)
  if(TPR_SANITIZE MATCHES "undefined")
    list(APPEND _tpr_san_flags -fno-sanitize-recover=undefined)
  endif()
  # GCC's flow warnings (-Wmaybe-uninitialized) change with the sanitizers'
  # instrumentation and gave false alarms the plain build does not (the
  # plain build keeps -Werror and is what CI checks warnings with): keep
  # the warnings visible, drop -Werror here.
  list(REMOVE_ITEM TPR_WARNINGS -Werror)
  add_compile_options(${_tpr_san_flags})
  add_link_options(-fsanitize=${TPR_SANITIZE})
  if(TPR_SANITIZE MATCHES "thread")
    # tpr::common::Mutex (common/mutex.h) is then std::shared_mutex and
    # std::condition_variable_any instead of absl::Mutex: Debian's libabsl is
    # not instrumented, so TSan cannot see an absl::Mutex's lock.
    add_compile_definitions(TPR_SYNC_STD=1)
  endif()
  message(STATUS "TPR_SANITIZE=${TPR_SANITIZE}")
endif()
