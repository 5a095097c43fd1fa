# libmr.so exports only the public API (MR_API, mr/export.h): no symbol of render/, photo/,
# core/'s private helpers (mr::render::, mr::photo::, mr::detail::, mr::gpu::) or of the
# anonymous namespaces, and the public entry points are there.
#   cmake -DLIBRARY=<libmr.so> -DNM=<nm> -P tests/exported_symbols_check.cmake
cmake_minimum_required(VERSION 3.25)
execute_process(COMMAND ${NM} -D --defined-only -C ${LIBRARY} OUTPUT_VARIABLE symbols
                RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "${NM} failed on ${LIBRARY}")
endif()
string(REPLACE "\n" ";" lines "${symbols}")
set(count 0)
set(private 0)
foreach(line ${lines})
  math(EXPR count "${count} + 1")
  if(line MATCHES "mr::(render|photo|detail|gpu)::|anonymous namespace")
    message(SEND_ERROR "exported private symbol: ${line}")
    math(EXPR private "${private} + 1")
  endif()
endforeach()
foreach(api "mr::fog(" "mr::render_scattering(" "mr::read_image(" "mr::estimate_scene("
            "mr::transfer_material(" "typeinfo for mr::Error")
  string(FIND "${symbols}" "${api}" at)
  if(at EQUAL -1)
    message(SEND_ERROR "not exported: ${api}")
  endif()
endforeach()
message(STATUS "${LIBRARY}: ${count} exported symbols, ${private} private")
