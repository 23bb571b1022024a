# The product builds without the test tools and installs where deploy/
# runs it. Run by CTest as build_product_install (label unit):
#   1. `cmake -DTPR_BUILD_TESTS=OFF` configures a fresh build directory
#      (configure only) without looking for GoogleTest, Google Benchmark or
#      LEMON, and defines no test; its install prefix defaults to /usr/local;
#   2. `cmake --install` of the existing build BINARY into a scratch prefix
#      yields exactly the product's commands in bin/, each runnable, and
#      every /usr/local/bin command a systemd unit in deploy/systemd starts.
#
#   cmake -DSOURCE=<tree> -DBINARY=<build> -DWORK=<scratch> -DGENERATOR=<gen>
#         -P tests/check_install.cmake
cmake_minimum_required(VERSION 3.25)  # policies: IN_LIST
foreach(var SOURCE BINARY WORK GENERATOR)
  if(NOT ${var})
    message(FATAL_ERROR "check_install.cmake: -D${var}=... is required")
  endif()
endforeach()
set(expected tpr tpr-eval-local tpr-extractor tpr-gateway tpr-indexer tpr-synth tpr-web)

# 1. A product-only configure.
set(notests ${WORK}/notests)
file(REMOVE_RECURSE ${notests})
execute_process(
  COMMAND ${CMAKE_COMMAND} -S ${SOURCE} -B ${notests} -G "${GENERATOR}"
          -DTPR_BUILD_TESTS=OFF -DCMAKE_BUILD_TYPE=Release
  RESULT_VARIABLE result OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT result EQUAL 0)
  message(FATAL_ERROR "cmake -DTPR_BUILD_TESTS=OFF failed to configure:\n${out}${err}")
endif()
file(STRINGS ${notests}/CMakeCache.txt cache)
list(FILTER cache EXCLUDE REGEX "^//")
foreach(probe GTest_DIR benchmark_DIR LEMON_INCLUDE_DIR LEMON_LIBRARY)
  set(hits ${cache})
  list(FILTER hits INCLUDE REGEX "^${probe}:")
  if(hits)
    message(FATAL_ERROR "TPR_BUILD_TESTS=OFF still looked for a test tool: ${hits}")
  endif()
endforeach()
set(prefix_line ${cache})
list(FILTER prefix_line INCLUDE REGEX "^CMAKE_INSTALL_PREFIX:")
if(NOT prefix_line MATCHES "=/usr/local$")
  message(FATAL_ERROR "default install prefix is not /usr/local: ${prefix_line}")
endif()
if(EXISTS ${notests}/tests OR EXISTS ${notests}/CTestTestfile.cmake)
  message(FATAL_ERROR "TPR_BUILD_TESTS=OFF still defines the tests (${notests}/tests)")
endif()
file(REMOVE_RECURSE ${notests})

# 2. Install the existing build into a scratch prefix.
set(prefix ${WORK}/prefix)
file(REMOVE_RECURSE ${prefix})
execute_process(COMMAND ${CMAKE_COMMAND} --install ${BINARY} --prefix ${prefix}
                RESULT_VARIABLE result OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT result EQUAL 0)
  message(FATAL_ERROR "cmake --install failed:\n${out}${err}")
endif()
file(GLOB installed RELATIVE ${prefix}/bin ${prefix}/bin/*)
list(SORT installed)
if(NOT installed STREQUAL expected)
  message(FATAL_ERROR "bin/ holds [${installed}], expected [${expected}]")
endif()
foreach(exe IN LISTS expected)
  execute_process(COMMAND ${prefix}/bin/${exe} --help
                  RESULT_VARIABLE result OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT result EQUAL 0)
    message(FATAL_ERROR "installed ${exe} --help exited ${result}:\n${out}${err}")
  endif()
endforeach()

# Every command the systemd units start from /usr/local/bin is installed.
file(GLOB units ${SOURCE}/deploy/systemd/*.service)
if(NOT units)
  message(FATAL_ERROR "no systemd units in ${SOURCE}/deploy/systemd")
endif()
foreach(unit IN LISTS units)
  file(STRINGS ${unit} starts REGEX "^ExecStart=")
  foreach(line IN LISTS starts)
    if(NOT line MATCHES "^ExecStart=/usr/local/bin/([^ ]+)")
      message(FATAL_ERROR "${unit}: ExecStart does not run from /usr/local/bin: ${line}")
    endif()
    if(NOT CMAKE_MATCH_1 IN_LIST expected)
      message(FATAL_ERROR "${unit} starts ${CMAKE_MATCH_1}, which is not installed")
    endif()
  endforeach()
endforeach()
file(REMOVE_RECURSE ${prefix})
message(STATUS "TPR_BUILD_TESTS=OFF configures without test tools; install yields ${expected}")
