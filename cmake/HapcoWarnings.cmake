# Warnings as an INTERFACE target: every HapCo target links hapco::warnings (design.md, ex. 9).
add_library(hapco_warnings INTERFACE)
add_library(hapco::warnings ALIAS hapco_warnings)
target_compile_options(hapco_warnings INTERFACE
  $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor
                            -Wold-style-cast -Wcast-align -Woverloaded-virtual
                            -Wdouble-promotion -Wformat=2>
  $<$<BOOL:${HAPCO_WARNINGS_AS_ERRORS}>:-Werror>)
