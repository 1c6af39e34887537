# All dependencies come from Debian packages (scripts/install-deps lists them).
find_package(Eigen3 3.3 REQUIRED NO_MODULE)
find_package(Protobuf REQUIRED)
find_package(CycloneDDS REQUIRED)
find_package(Threads REQUIRED)
find_package(PkgConfig REQUIRED)
# LAPACK (liblapack-dev; OpenBLAS's when installed): dpotri for the contact compliance block.
find_package(LAPACK REQUIRED)

# CHOLMOD (SuiteSparse 5.x on Debian 12 ships no CMake config): an imported target by hand.
find_path(CHOLMOD_INCLUDE_DIR cholmod.h PATH_SUFFIXES suitesparse REQUIRED)
find_library(CHOLMOD_LIBRARY cholmod REQUIRED)
find_library(SUITESPARSECONFIG_LIBRARY suitesparseconfig REQUIRED)
add_library(hapco_cholmod INTERFACE)
add_library(SuiteSparse::CHOLMOD ALIAS hapco_cholmod)
target_include_directories(hapco_cholmod SYSTEM INTERFACE ${CHOLMOD_INCLUDE_DIR})
target_link_libraries(hapco_cholmod INTERFACE ${CHOLMOD_LIBRARY} ${SUITESPARSECONFIG_LIBRARY})

# FCLIB (HDF5 frictional-contact problem files), pkg-config name `fclib`.
if(HAPCO_WITH_FCLIB)
  pkg_check_modules(FCLIB REQUIRED IMPORTED_TARGET fclib)
endif()

# Gmsh's C++ API (gmsh.h, libgmsh; Debian ships no CMake config): an imported target by hand.
if(HAPCO_WITH_GMSH AND NOT HAPCO_BUILD_FUZZERS)
  find_path(GMSH_INCLUDE_DIR gmsh.h)
  find_library(GMSH_LIBRARY gmsh)
  if(NOT GMSH_INCLUDE_DIR OR NOT GMSH_LIBRARY)
    message(FATAL_ERROR "Gmsh not found: apt-get install libgmsh-dev (scripts/install-deps), or -DHAPCO_WITH_GMSH=OFF")
  endif()
  add_library(hapco_gmsh INTERFACE)
  add_library(Gmsh::gmsh ALIAS hapco_gmsh)
  target_include_directories(hapco_gmsh SYSTEM INTERFACE ${GMSH_INCLUDE_DIR})
  target_link_libraries(hapco_gmsh INTERFACE ${GMSH_LIBRARY})
endif()

# Siconos Numerics is optional: only the contact benchmark compares against it.
find_path(SICONOS_NUMERICS_INCLUDE_DIR FrictionContactProblem.h PATH_SUFFIXES siconos/numerics)
find_library(SICONOS_NUMERICS_LIBRARY siconos_numerics)
find_library(SICONOS_EXTERNALS_LIBRARY siconos_externals)
if(SICONOS_NUMERICS_INCLUDE_DIR AND SICONOS_NUMERICS_LIBRARY AND SICONOS_EXTERNALS_LIBRARY)
  set(HAPCO_HAVE_SICONOS ON)
  add_library(hapco_siconos INTERFACE)
  add_library(Siconos::numerics ALIAS hapco_siconos)
  get_filename_component(_siconos_root ${SICONOS_NUMERICS_INCLUDE_DIR} DIRECTORY)
  target_include_directories(hapco_siconos SYSTEM INTERFACE ${SICONOS_NUMERICS_INCLUDE_DIR} ${_siconos_root})
  target_link_libraries(hapco_siconos INTERFACE ${SICONOS_NUMERICS_LIBRARY} ${SICONOS_EXTERNALS_LIBRARY})
  message(STATUS "Siconos Numerics found: the contact benchmark compares against it")
else()
  set(HAPCO_HAVE_SICONOS OFF)
  message(STATUS "Siconos Numerics not found: contact benchmark runs HapCo solvers only")
endif()

if(HAPCO_BUILD_TESTS)
  find_package(GTest REQUIRED)
  find_package(benchmark QUIET)
endif()
