# The include rules of the layering (README "Layout"), checked on the
# sources under ROOT. Run by CTest as layering_pure_libraries; the test
# layering_check_refuses (check_layering_refuses.cmake) runs it on trees
# that break each rule and requires it to fail, naming the file.
#
#   cmake -DROOT=<source tree> -P tests/check_layering.cmake
#
# Rules, by folder (direct #include lines of *.h and *.cc):
# - every pure library (extractor/lib, extractor/synth, indexer/lib,
#   eval/lib): no gRPC, Protobuf, RocksDB or generated contract (tpr/v1/);
#   no service, gateway or client header; from common/ only status_macros.h,
#   parallel.h, signature_limits.h and json_text.h (the other common/ headers are server
#   plumbing over gRPC);
# - extractor/lib and extractor/synth: nothing from indexer/ or eval/ (the
#   halves never see each other; eval/lib bridges them);
# - indexer/lib: nothing from extractor/ or eval/;
# - common/ (shared by everything): nothing from extractor/, indexer/
#   (gateway included), eval/, client/ (nor the SDK's tpr/ headers) or
#   web/, and no service contract (tpr/v1/extractor, tpr/v1/indexer); the services feed it what it needs
#   (metrics observers, the roles declared in the contract's options).
if(NOT ROOT)
  message(FATAL_ERROR "usage: cmake -DROOT=<source tree> -P check_layering.cmake")
endif()

set(system_regex "#include [<\"](grpc|grpcpp|google/protobuf|rocksdb|tpr/v1/)")
set(service_regex "#include \"([a-z_]+/)*(service|gateway)/|#include \"client/")
set(common_regex "#include \"common/")
set(failures "")

# check(<dir> <regex> <what>): appends each file under ROOT/<dir> whose
# include lines match <regex>.
function(check dir regex what)
  file(GLOB files ${ROOT}/${dir}/*.h ${ROOT}/${dir}/*.cc)
  foreach(f IN LISTS files)
    file(STRINGS ${f} hits REGEX "${regex}")
    if(hits)
      string(APPEND failures "${f}: ${what}: ${hits}\n")
    endif()
  endforeach()
  set(failures "${failures}" PARENT_SCOPE)
endfunction()

set(pure_dirs extractor/lib extractor/synth indexer/lib eval/lib)
foreach(dir IN LISTS pure_dirs)
  check(${dir} "${system_regex}" "a pure library includes gRPC, Protobuf, RocksDB or the contract")
  check(${dir} "${service_regex}" "a pure library includes a service, gateway or client header")
  file(GLOB files ${ROOT}/${dir}/*.h ${ROOT}/${dir}/*.cc)
  foreach(f IN LISTS files)
    file(STRINGS ${f} hits REGEX "${common_regex}")
    list(FILTER hits EXCLUDE REGEX "#include \"common/(status_macros|parallel|signature_limits|json_text)\\.h\"")
    if(hits)
      string(APPEND failures "${f}: a pure library includes server plumbing from common/: ${hits}\n")
    endif()
  endforeach()
endforeach()
foreach(dir extractor/lib extractor/synth)
  check(${dir} "#include \"(indexer|eval)/" "the extractor includes the indexer or eval")
endforeach()
check(indexer/lib "#include \"(extractor|eval)/" "the indexer library includes the extractor or eval")
check(common "#include [<\"]((extractor|indexer|eval|client|web)/|tpr/[^v]|tpr/v1/(extractor|indexer)[.])"
      "common/ includes code above it")

if(failures)
  message(FATAL_ERROR "layering broken:\n${failures}")
endif()
message(STATUS "layering holds: pure libraries include no gRPC/Protobuf/RocksDB, "
               "service or server header; extractor and indexer libraries apart; "
               "common/ below them all")
