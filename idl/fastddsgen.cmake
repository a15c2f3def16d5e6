# Runs fastddsgen quietly (it is chatty) and fails loudly with its output when it fails.
# Usage: cmake -DFASTDDSGEN=... -DIDL=... -DINCLUDE_DIR=... -DOUT_DIR=... -P fastddsgen.cmake
file(MAKE_DIRECTORY ${OUT_DIR})
execute_process(
  COMMAND ${FASTDDSGEN} -replace -I ${INCLUDE_DIR} -d ${OUT_DIR} ${IDL}
  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE out)
if(NOT rc EQUAL 0 OR out MATCHES "ERROR")
  message(FATAL_ERROR "fastddsgen failed on ${IDL}:\n${out}")
endif()
