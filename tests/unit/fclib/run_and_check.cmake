# Runs a command and checks both its exit code and its output (ctest alone can check one or
# the other). Usage:
#   cmake -DCOMMAND="exe;arg;..." -DEXPECT_EXIT=N -DEXPECT_REGEX="..." [-DFORBID_REGEX="..."]
#         -P run_and_check.cmake
execute_process(COMMAND ${COMMAND} RESULT_VARIABLE code OUTPUT_VARIABLE out ERROR_VARIABLE err)
message("${out}${err}")
if(NOT code STREQUAL "${EXPECT_EXIT}")
  message(FATAL_ERROR "exit code ${code}, expected ${EXPECT_EXIT}")
endif()
if(DEFINED EXPECT_REGEX AND NOT "${out}${err}" MATCHES "${EXPECT_REGEX}")
  message(FATAL_ERROR "output does not match '${EXPECT_REGEX}'")
endif()
if(DEFINED FORBID_REGEX AND "${out}${err}" MATCHES "${FORBID_REGEX}")
  message(FATAL_ERROR "output matches forbidden '${FORBID_REGEX}'")
endif()
