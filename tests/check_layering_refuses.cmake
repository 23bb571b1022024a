# Proves that check_layering.cmake can fail: for each rule, a scratch tree
# under WORK with one file that breaks it must make the check fail and name
# that file; a tree that keeps every rule must pass. Run by CTest as
# layering_check_refuses.
#
#   cmake -DWORK=<scratch dir> -DCHECK=<check_layering.cmake> -P check_layering_refuses.cmake
if(NOT WORK OR NOT CHECK)
  message(FATAL_ERROR "usage: cmake -DWORK=<dir> -DCHECK=<check_layering.cmake> -P ...")
endif()

# run_check(<tree> <out-result> <out-output>)
function(run_check tree result_var output_var)
  execute_process(COMMAND ${CMAKE_COMMAND} -DROOT=${tree} -P ${CHECK}
                  RESULT_VARIABLE result OUTPUT_VARIABLE out ERROR_VARIABLE err)
  set(${result_var} ${result} PARENT_SCOPE)
  set(${output_var} "${out}${err}" PARENT_SCOPE)
endfunction()

# A tree that keeps every rule: each pure library includes what it may.
set(good ${WORK}/good)
file(REMOVE_RECURSE ${good})
file(WRITE ${good}/extractor/lib/a.h "#include \"extractor/lib/mesh.h\"\n#include \"common/status_macros.h\"\n#include \"common/parallel.h\"\n")
file(WRITE ${good}/indexer/lib/a.cc "#include \"indexer/lib/emd.h\"\n#include <vector>\n")
file(WRITE ${good}/eval/lib/a.h "#include \"extractor/lib/signature.h\"\n#include \"indexer/lib/signature.h\"\n")
file(WRITE ${good}/common/a.cc "#include \"common/auth.h\"\n#include \"tpr/v1/access.pb.h\"\n")
file(WRITE ${good}/extractor/service/a.cc "#include <grpcpp/grpcpp.h>\n#include \"indexer/lib/signature.h\"\n")
run_check(${good} result output)
if(NOT result EQUAL 0)
  message(FATAL_ERROR "the check refused a tree that keeps every rule:\n${output}")
endif()

# Each case: <folder>/<file>|<include line>. The file must be named.
set(cases
  "extractor/lib/bad.h|#include \"indexer/lib/signature.h\""
  "extractor/lib/bad.cc|#include \"eval/lib/metrics.h\""
  "extractor/synth/bad.cc|#include \"indexer/lib/emd.h\""
  "extractor/lib/bad.h|#include \"extractor/service/convert.h\""
  "extractor/lib/bad.h|#include \"indexer/service/storage.h\""
  "extractor/lib/bad.cc|#include \"indexer/gateway/shard_map.h\""
  "extractor/lib/bad.cc|#include \"client/cli/command.h\""
  "extractor/lib/bad.cc|#include \"common/grpc_status.h\""
  "extractor/lib/bad.cc|#include <grpcpp/grpcpp.h>"
  "extractor/lib/bad.cc|#include \"tpr/v1/signature.pb.h\""
  "indexer/lib/bad.h|#include \"extractor/lib/signature.h\""
  "indexer/lib/bad.cc|#include \"indexer/service/convert.h\""
  "indexer/lib/bad.cc|#include <rocksdb/db.h>"
  "indexer/lib/bad.cc|#include \"common/config.h\""
  "eval/lib/bad.cc|#include \"extractor/service/convert.h\""
  "eval/lib/bad.cc|#include <google/protobuf/message.h>"
  "common/bad.cc|#include \"eval/lib/report.h\""
  "common/bad.h|#include \"extractor/lib/mesh.h\""
  "common/bad.cc|#include \"indexer/service/convert.h\""
  "common/bad.cc|#include \"indexer/gateway/shard_map.h\""
  "common/bad.cc|#include \"client/include/tpr/client.h\""
  "common/bad.cc|#include \"web/api.h\""
  "common/bad.cc|#include \"tpr/client.h\""
  "common/bad.cc|#include \"tpr/v1/indexer.pb.h\""
  "common/bad.cc|#include \"tpr/v1/extractor.grpc.pb.h\"")
set(i 0)
foreach(case IN LISTS cases)
  string(FIND "${case}" "|" bar)
  string(SUBSTRING "${case}" 0 ${bar} file)
  math(EXPR rest "${bar} + 1")
  string(SUBSTRING "${case}" ${rest} -1 line)
  set(tree ${WORK}/case${i})
  math(EXPR i "${i} + 1")
  file(REMOVE_RECURSE ${tree})
  file(COPY ${good}/ DESTINATION ${tree})
  file(WRITE ${tree}/${file} "// fixture\n${line}\n")
  run_check(${tree} result output)
  if(result EQUAL 0)
    message(FATAL_ERROR "the check passed ${file} including ${line}")
  endif()
  string(FIND "${output}" "${tree}/${file}" named)
  if(named EQUAL -1)
    message(FATAL_ERROR "the check failed without naming ${file} (${line}):\n${output}")
  endif()
endforeach()
message(STATUS "check_layering refused all ${i} broken trees and passed the good one")
