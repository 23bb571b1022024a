# Helpers that turn a folder of sources into targets, so that adding a file
# needs no CMake edit. Convention, per folder:
#   *.cc except main.cc and *_main.cc -> a static library
#   main.cc or <name>_main.cc         -> an executable linking that library
include_guard(GLOBAL)

# tpr_folder_library(<target> <dir> [PUBLIC libs...] [PRIVATE libs...])
# Creates <target> from <dir>/*.cc and *.h (mains excluded); a folder with
# no source is a configuration error, not an empty target.
function(tpr_folder_library target dir)
  cmake_parse_arguments(ARG "" "" "PUBLIC;PRIVATE" ${ARGN})
  file(GLOB srcs CONFIGURE_DEPENDS ${dir}/*.cc)
  file(GLOB hdrs CONFIGURE_DEPENDS ${dir}/*.h)
  list(FILTER srcs EXCLUDE REGEX "(/main\\.cc|_main\\.cc)$")
  if(NOT srcs)
    message(FATAL_ERROR "${target}: no sources in ${dir}")
  endif()
  add_library(${target} STATIC ${srcs} ${hdrs})
  set_target_properties(${target} PROPERTIES LINKER_LANGUAGE CXX)
  target_compile_options(${target} PRIVATE ${TPR_WARNINGS})
  target_link_libraries(${target} PUBLIC tpr_common ${ARG_PUBLIC} PRIVATE ${ARG_PRIVATE})
endfunction()

# tpr_folder_executable(<exe-name> <main.cc> LIBS libs...)
function(tpr_folder_executable name main)
  cmake_parse_arguments(ARG "" "" "LIBS" ${ARGN})
  add_executable(${name} ${main})
  target_compile_options(${name} PRIVATE ${TPR_WARNINGS})
  target_link_libraries(${name} PRIVATE ${ARG_LIBS})
endfunction()
