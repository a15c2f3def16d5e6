# Runs fastddsgen quietly (it is chatty) and fails loudly with its output when it fails.
# Usage: cmake -DFASTDDSGEN=... -DIDL=... -DINCLUDE_DIR=... -DOUT_DIR=... -P fastddsgen.cmake
#
# fastddsgen also regenerates every IDL file the given one includes. With one command per IDL
# running in parallel, those rewrites raced with compiles of the same files (a clean -j2 build
# once found nav_msgsPubSubTypes.cxx missing). So each run writes into a private scratch folder
# and only the given IDL's own four files are copied out.
get_filename_component(name ${IDL} NAME_WE)
set(scratch ${OUT_DIR}/.scratch-${name})
file(REMOVE_RECURSE ${scratch})
file(MAKE_DIRECTORY ${scratch} ${OUT_DIR})
execute_process(
  COMMAND ${FASTDDSGEN} -replace -I ${INCLUDE_DIR} -d ${scratch} ${IDL}
  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
if(NOT rc EQUAL 0 OR out MATCHES "ERROR")
  message(FATAL_ERROR "fastddsgen failed on ${IDL}:\n${out}")
endif()
foreach(suffix .cxx .h PubSubTypes.cxx PubSubTypes.h)
  if(NOT EXISTS ${scratch}/${name}${suffix})
    message(FATAL_ERROR "fastddsgen did not write ${name}${suffix}")
  endif()
  execute_process(COMMAND ${CMAKE_COMMAND} -E copy_if_different ${scratch}/${name}${suffix}
                          ${OUT_DIR}/${name}${suffix})
endforeach()
file(REMOVE_RECURSE ${scratch})
