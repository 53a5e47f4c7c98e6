# One fuzzer's smoke run (tests/fuzz/CMakeLists.txt): FUZZER for SECONDS over a scratch copy of
# the seed corpus SEEDS in WORK. libFuzzer exits non-zero on a finding (crash, sanitizer
# report, leak, timeout of one input, or more than 2 GiB of RSS) and writes the input as
# WORK/crash-* (or leak-*, timeout-*, oom-*), which the failure message names.
file(REMOVE_RECURSE ${WORK})
file(MAKE_DIRECTORY ${WORK}/corpus)
file(GLOB seeds ${SEEDS}/*)
file(COPY ${seeds} DESTINATION ${WORK}/corpus)
execute_process(
  COMMAND ${FUZZER} -max_total_time=${SECONDS} -timeout=10 -rss_limit_mb=2048
    -malloc_limit_mb=2048 -print_final_stats=1 -artifact_prefix=${WORK}/ ${WORK}/corpus
  WORKING_DIRECTORY ${WORK}
  RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  file(GLOB found ${WORK}/crash-* ${WORK}/leak-* ${WORK}/timeout-* ${WORK}/oom-*)
  message(FATAL_ERROR "${FUZZER} found a problem (exit ${rc}): ${found}")
endif()
