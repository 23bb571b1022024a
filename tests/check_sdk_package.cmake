# The C++ SDK as an installed package, consumed from outside the source tree.
# Run by CTest as sdk_package (label install):
#   1. `cmake --install BINARY --component sdk` into a scratch prefix under
#      the system's temporary folder yields the public headers (tpr/client.h,
#      tpr/connection.h, the generated tpr/v1/*.pb.h they include) and no
#      server-only header, libtpr_client.a and .so, the CMake package and
#      tpr.pc;
#   2. examples/ (find_package(tpr), tpr::client) configures and builds
#      against that prefix, and its program runs (usage: exit 2);
#   3. the same source compiles and links with `pkg-config --cflags --libs
#      tpr` alone (the shared library) and runs.
#
#   cmake -DSOURCE=<tree> -DBINARY=<build> -DGENERATOR=<gen>
#         -P tests/check_sdk_package.cmake
cmake_minimum_required(VERSION 3.25)
foreach(var SOURCE BINARY GENERATOR)
  if(NOT ${var})
    message(FATAL_ERROR "check_sdk_package.cmake: -D${var}=... is required")
  endif()
endforeach()
set(tmp $ENV{TMPDIR})
if(NOT tmp)
  set(tmp /tmp)
endif()
string(RANDOM LENGTH 8 suffix)
set(work ${tmp}/tpr-sdk-package-${suffix})
set(prefix ${work}/prefix)
file(REMOVE_RECURSE ${work})

function(run what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE result
                  OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT result EQUAL 0)
    file(REMOVE_RECURSE ${work})
    message(FATAL_ERROR "${what} failed (${result}):\n${out}${err}")
  endif()
endfunction()

# 1. Install the SDK alone.
run("cmake --install --component sdk"
    ${CMAKE_COMMAND} --install ${BINARY} --component sdk --prefix ${prefix})
foreach(file include/tpr/client.h include/tpr/connection.h
             include/tpr/v1/indexer.grpc.pb.h include/tpr/v1/signature.pb.h
             lib/libtpr_client.a lib/libtpr_client.so lib/cmake/tpr/tprConfig.cmake
             lib/cmake/tpr/tprConfigVersion.cmake lib/pkgconfig/tpr.pc)
  if(NOT EXISTS ${prefix}/${file})
    file(REMOVE_RECURSE ${work})
    message(FATAL_ERROR "the SDK install lacks ${file}")
  endif()
endforeach()
# Every quoted include of an installed header is installed too (no header
# of the source tree, e.g. common/ or client/peer/connection_flags.h).
file(GLOB_RECURSE headers ${prefix}/include/*.h)
foreach(header IN LISTS headers)
  file(STRINGS ${header} includes REGEX "^#include \"")
  foreach(line IN LISTS includes)
    string(REGEX REPLACE "^#include \"([^\"]+)\".*" "\\1" name "${line}")
    if(NOT EXISTS ${prefix}/include/${name} AND NOT name MATCHES "^(absl|google|grpc)")
      file(REMOVE_RECURSE ${work})
      message(FATAL_ERROR "${header} includes ${name}, which is not installed")
    endif()
  endforeach()
endforeach()

# 2. examples/ through find_package(tpr).
run("configuring examples/ against the package"
    ${CMAKE_COMMAND} -S ${SOURCE}/examples -B ${work}/example -G "${GENERATOR}"
    -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_BUILD_TYPE=Release)
run("building examples/" ${CMAKE_COMMAND} --build ${work}/example)
execute_process(COMMAND ${work}/example/similar RESULT_VARIABLE result
                OUTPUT_QUIET ERROR_QUIET)
if(NOT result EQUAL 2)
  file(REMOVE_RECURSE ${work})
  message(FATAL_ERROR "examples/similar without arguments exited ${result}, not 2")
endif()

# 3. pkg-config alone.
set(ENV{PKG_CONFIG_PATH} ${prefix}/lib/pkgconfig)
execute_process(COMMAND pkg-config --cflags --libs tpr RESULT_VARIABLE result
                OUTPUT_VARIABLE flags ERROR_VARIABLE err
                OUTPUT_STRIP_TRAILING_WHITESPACE)
if(NOT result EQUAL 0)
  file(REMOVE_RECURSE ${work})
  message(FATAL_ERROR "pkg-config --cflags --libs tpr failed:\n${err}")
endif()
separate_arguments(flags UNIX_COMMAND "${flags}")
run("c++ with pkg-config's flags"
    c++ -std=c++17 ${SOURCE}/examples/similar.cc -o ${work}/similar_pc ${flags})
set(ENV{LD_LIBRARY_PATH} ${prefix}/lib)
execute_process(COMMAND ${work}/similar_pc RESULT_VARIABLE result
                OUTPUT_QUIET ERROR_QUIET)
if(NOT result EQUAL 2)
  file(REMOVE_RECURSE ${work})
  message(FATAL_ERROR "the pkg-config build without arguments exited ${result}, not 2")
endif()
file(REMOVE_RECURSE ${work})
message(STATUS "the SDK installs as a package; examples/ builds with find_package(tpr) and with pkg-config")
