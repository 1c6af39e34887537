# libFuzzer + AddressSanitizer + UBSan for the fuzz tree (preset `fuzz`, docs/fuzzing.md).
# Libraries are instrumented for coverage (fuzzer-no-link); only the harness executables link
# the libFuzzer driver (hapco_add_fuzzer in tests/fuzz). UB is fatal so that the fuzzer
# stops on it and keeps the input. The preset builds -O1 without NDEBUG: Eigen's index
# assertions stay on, and sanitized code compiles about twice as fast as at -O3.
if(NOT CMAKE_CXX_COMPILER_ID MATCHES "Clang")
  message(FATAL_ERROR "HAPCO_BUILD_FUZZERS needs clang (libFuzzer): use the `fuzz` preset "
                      "(CMAKE_CXX_COMPILER=clang++); got ${CMAKE_CXX_COMPILER_ID}")
endif()
set(HAPCO_SANITIZERS address,undefined)
add_compile_options(-fsanitize=fuzzer-no-link,${HAPCO_SANITIZERS} -fno-sanitize-recover=undefined
                    -fno-omit-frame-pointer -gline-tables-only)
add_link_options(-fsanitize=${HAPCO_SANITIZERS})
