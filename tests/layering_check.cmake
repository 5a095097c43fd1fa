# The layers read one way (docs/architecture.md):
#   cli/, gui/ -> libmr/include/mr/ (public API) -> libmr/src/ (API layer) -> photo/ -> render/ -> core/
# Every quoted #include in a layer must name a header of its own layer or of one below it; the
# front ends use only the public headers. libmr/include/mr/ holds two kinds of header: the core
# types every layer shares (listed below), and the API (fog.h, estimate.h, material.h, ...) that
# only the API layer and the front ends may include.
#   cmake -DSOURCE_DIR=<repo> -P tests/layering_check.cmake
# Prints every violation as "file:line: includes X (layer L may include only ...)" and fails.
cmake_minimum_required(VERSION 3.25)
set(core_types annotations camera cancel error export image material_model metadata objects scene vec3 version)
list(TRANSFORM core_types PREPEND "mr/")
list(TRANSFORM core_types APPEND ".h")

# check(<folder> <allowed prefixes...>): quoted includes must start with an allowed prefix, be a
# core-type header, or name a file beside the including one (no slash).
function(check folder)
  set(allowed ${ARGN})
  file(GLOB_RECURSE files ${SOURCE_DIR}/${folder}/*.h ${SOURCE_DIR}/${folder}/*.cpp ${SOURCE_DIR}/${folder}/*.inc)
  foreach(f ${files})
    file(STRINGS ${f} lines REGEX "^[ \t]*#[ \t]*include[ \t]*\"")
    foreach(line ${lines})
      string(REGEX REPLACE "^[ \t]*#[ \t]*include[ \t]*\"([^\"]+)\".*" "\\1" inc "${line}")
      set(ok FALSE)
      get_filename_component(dir ${f} DIRECTORY)
      if(NOT inc MATCHES "/" AND (EXISTS ${dir}/${inc} OR inc MATCHES "\\.(comp|vert|frag)\\.inc$"))
        set(ok TRUE)  # beside the including file, or SPIR-V generated from shaders/
      endif()
      foreach(prefix ${allowed})
        string(FIND "${inc}" "${prefix}" at)
        if(at EQUAL 0)
          set(ok TRUE)
        endif()
      endforeach()
      if(NOT ok AND "core_types" IN_LIST allowed AND inc IN_LIST core_types)
        set(ok TRUE)
      endif()
      if(NOT ok)
        file(RELATIVE_PATH rel ${SOURCE_DIR} ${f})
        message(SEND_ERROR "${rel}: includes \"${inc}\" (${folder}/ may include only: ${allowed})")
      endif()
    endforeach()
  endforeach()
endfunction()

check(core core/ core_types)
check(render render/ shaders/ core/ core_types)
check(photo photo/ render/ shaders/ core/ core_types)
check(libmr/include/mr mr/)
check(cli mr/)
check(gui mr/)
# The core-type headers themselves include only core-type headers.
foreach(h ${core_types})
  file(STRINGS ${SOURCE_DIR}/libmr/include/${h} lines REGEX "^#include \"")
  foreach(line ${lines})
    string(REGEX REPLACE "^#include \"([^\"]+)\".*" "\\1" inc "${line}")
    if(NOT inc IN_LIST core_types)
      message(SEND_ERROR "libmr/include/${h}: a core-type header includes the API header \"${inc}\"")
    endif()
  endforeach()
endforeach()
