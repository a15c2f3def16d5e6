# Runs fastddsgen quietly (it is chatty) on each IDL file in turn and fails loudly with its
# output when it fails.
# Usage: cmake -DFASTDDSGEN=... -DIDLS=a.idl|b.idl -DINCLUDE_DIR=... -DOUT_DIR=... -P fastddsgen.cmake
#
# One process for all files, one file at a time: fastddsgen also regenerates every IDL a file
# includes, and concurrent runs interfered (clean -j2 builds lost *PubSubTypes.cxx, or a run
# wrote another IDL's output). Each run writes into a scratch folder and only the given IDL's
# own four files are copied out, so unchanged files keep their timestamps.
file(MAKE_DIRECTORY ${OUT_DIR})
string(REPLACE "|" ";" idl_list "${IDLS}")
foreach(IDL IN LISTS idl_list)
  get_filename_component(name ${IDL} NAME_WE)
  set(scratch ${OUT_DIR}/.scratch)
  file(REMOVE_RECURSE ${scratch})
  file(MAKE_DIRECTORY ${scratch})
  execute_process(
    COMMAND ${FASTDDSGEN} -replace -I ${INCLUDE_DIR} -d ${scratch} ${IDL}
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
  if(NOT rc EQUAL 0 OR out MATCHES "ERROR")
    message(FATAL_ERROR "fastddsgen failed on ${IDL}:\n${out}")
  endif()
  foreach(suffix .cxx .h PubSubTypes.cxx PubSubTypes.h)
    if(NOT EXISTS ${scratch}/${name}${suffix})
      message(FATAL_ERROR "fastddsgen did not write ${name}${suffix}:\n${out}")
    endif()
    execute_process(COMMAND ${CMAKE_COMMAND} -E copy_if_different ${scratch}/${name}${suffix}
                            ${OUT_DIR}/${name}${suffix})
  endforeach()
endforeach()
file(REMOVE_RECURSE ${OUT_DIR}/.scratch)
