# package_test.cmake: kiln_runtime as a package, end to end (ctest -R package; cmake -P).
#  1. cmake --install <build> --component runtime into a fresh prefix; the installed files are
#     exactly the runtime's: every header of probes/runtime/include plus kiln/version.h, the
#     library, the CMake package and the pkg-config file (nothing missing, nothing else);
#  2. tests/package/consumer (a C99 and a C++ program that load probes, blend them and check
#     the irradiance of a constant radiance, E = pi L, and the version) configured against
#     the prefix with find_package(kiln), built and run;
#  3. the C program compiled and linked with `pkg-config --cflags --libs kiln-runtime` alone
#     and run;
#  4. the consumer with add_subdirectory(probes/runtime) instead: configured, built and run.
# Any failure stops with FATAL_ERROR (non-zero exit) and the failing command's output.
# Inputs (-D): KILN_BUILD_DIR, KILN_SOURCE_DIR, KILN_WORK_DIR (emptied first), KILN_VERSION,
# KILN_LIBDIR, KILN_INCLUDEDIR, KILN_GENERATOR, KILN_C_COMPILER, KILN_CXX_COMPILER,
# KILN_BUILD_TYPE, and optionally KILN_C_LAUNCHER, KILN_CXX_LAUNCHER, KILN_PKG_CONFIG,
# KILN_CONFIG (the configuration to install, for multi-config generators).
cmake_minimum_required(VERSION 3.22)

foreach(var KILN_BUILD_DIR KILN_SOURCE_DIR KILN_WORK_DIR KILN_VERSION KILN_LIBDIR
            KILN_INCLUDEDIR KILN_GENERATOR KILN_C_COMPILER KILN_CXX_COMPILER)
  if(NOT DEFINED ${var} OR "${${var}}" STREQUAL "")
    message(FATAL_ERROR "package_test.cmake: -D${var}=... is required")
  endif()
endforeach()

set(prefix ${KILN_WORK_DIR}/prefix)
set(consumer_source ${KILN_SOURCE_DIR}/tests/package/consumer)
set(runtime_source ${KILN_SOURCE_DIR}/probes/runtime)
file(REMOVE_RECURSE ${KILN_WORK_DIR})
file(MAKE_DIRECTORY ${KILN_WORK_DIR})

# Runs a command; stops the test with its output when it fails.
function(step name)
  string(TIMESTAMP start "%s")
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE result OUTPUT_VARIABLE out
                  ERROR_VARIABLE out TIMEOUT 300)
  string(TIMESTAMP stop "%s")
  math(EXPR seconds "${stop} - ${start}")
  if(NOT result EQUAL 0)
    list(JOIN ARGN " " command)
    message(FATAL_ERROR "package test: ${name} failed (${result}):\n  ${command}\n${out}")
  endif()
  message(STATUS "${name}: ok (${seconds} s)")
  set(step_output "${out}" PARENT_SCOPE)
endfunction()

# --- 1. install the runtime component ------------------------------------------------------
set(config_args)
if(KILN_CONFIG)
  set(config_args --config ${KILN_CONFIG})
endif()
step("install --component runtime" ${CMAKE_COMMAND} --install ${KILN_BUILD_DIR}
     --prefix ${prefix} --component runtime ${config_args})

set(cmake_dir ${KILN_LIBDIR}/cmake/kiln)
set(expected
  ${KILN_INCLUDEDIR}/kiln/version.h
  ${KILN_LIBDIR}/libkiln_runtime.a
  ${cmake_dir}/kilnConfig.cmake
  ${cmake_dir}/kilnConfigVersion.cmake
  ${cmake_dir}/kilnTargets.cmake
  ${KILN_LIBDIR}/pkgconfig/kiln-runtime.pc)
file(GLOB_RECURSE headers RELATIVE ${runtime_source}/include ${runtime_source}/include/*.h)
if(NOT "kiln_runtime.h" IN_LIST headers OR NOT "kiln/sh.h" IN_LIST headers)
  message(FATAL_ERROR "package test: no headers found under ${runtime_source}/include")
endif()
foreach(header IN LISTS headers)
  list(APPEND expected ${KILN_INCLUDEDIR}/${header})
endforeach()
file(GLOB_RECURSE installed RELATIVE ${prefix} ${prefix}/*)
set(problems "")
foreach(file IN LISTS expected)
  if(NOT file IN_LIST installed)
    string(APPEND problems "\n  missing: ${file}")
  endif()
endforeach()
foreach(file IN LISTS installed)
  # kilnTargets-<config>.cmake: one per installed configuration.
  if(NOT file IN_LIST expected AND NOT file MATCHES "^${cmake_dir}/kilnTargets-[a-z]+\\.cmake$")
    string(APPEND problems "\n  not part of the runtime: ${file}")
  endif()
endforeach()
if(problems)
  message(FATAL_ERROR "package test: the runtime component installs the wrong files:${problems}")
endif()
list(LENGTH installed count)
message(STATUS "installed files: ok (${count} files)")

# The export must tell C consumers to link with the C++ runtime (a static C++ library).
file(GLOB config_exports ${prefix}/${cmake_dir}/kilnTargets-*.cmake)
if(NOT config_exports)
  message(FATAL_ERROR "package test: no kilnTargets-<config>.cmake installed")
endif()
foreach(export IN LISTS config_exports)
  file(READ ${export} text)
  if(NOT text MATCHES "IMPORTED_LINK_INTERFACE_LANGUAGES_[A-Z]+ \"CXX\"")
    message(FATAL_ERROR "package test: ${export} lacks IMPORTED_LINK_INTERFACE_LANGUAGES CXX")
  endif()
endforeach()

# --- 2. and 4. the consumer project, from the package and through add_subdirectory ---------
set(consumer_args -G ${KILN_GENERATOR}
  -DCMAKE_C_COMPILER=${KILN_C_COMPILER} -DCMAKE_CXX_COMPILER=${KILN_CXX_COMPILER}
  -DKILN_EXPECTED_VERSION=${KILN_VERSION})
if(KILN_BUILD_TYPE)
  list(APPEND consumer_args -DCMAKE_BUILD_TYPE=${KILN_BUILD_TYPE})
endif()
if(KILN_C_LAUNCHER)
  list(APPEND consumer_args -DCMAKE_C_COMPILER_LAUNCHER=${KILN_C_LAUNCHER})
endif()
if(KILN_CXX_LAUNCHER)
  list(APPEND consumer_args -DCMAKE_CXX_COMPILER_LAUNCHER=${KILN_CXX_LAUNCHER})
endif()

function(consumer mode)
  set(build ${KILN_WORK_DIR}/consumer-${mode})
  step("consumer (${mode}): configure" ${CMAKE_COMMAND} -S ${consumer_source} -B ${build}
       ${consumer_args} -DKILN_CONSUMER_MODE=${mode} ${ARGN})
  step("consumer (${mode}): build" ${CMAKE_COMMAND} --build ${build} --parallel 2 ${config_args})
  foreach(program consumer_c consumer_cpp)
    set(exe ${build}/${program})
    if(KILN_CONFIG AND EXISTS ${build}/${KILN_CONFIG}/${program})
      set(exe ${build}/${KILN_CONFIG}/${program})
    endif()
    step("consumer (${mode}): run ${program}" ${exe} ${build})
  endforeach()
endfunction()

consumer(package -DCMAKE_PREFIX_PATH=${prefix})

# A project without CXX cannot link kiln::runtime into a C program: the package says why.
execute_process(COMMAND ${CMAKE_COMMAND} -S ${KILN_SOURCE_DIR}/tests/package/c_only
                -B ${KILN_WORK_DIR}/c-only -G ${KILN_GENERATOR}
                -DCMAKE_C_COMPILER=${KILN_C_COMPILER} -DCMAKE_PREFIX_PATH=${prefix}
                RESULT_VARIABLE result OUTPUT_VARIABLE out ERROR_VARIABLE out TIMEOUT 300)
string(REGEX REPLACE "[ \n]+" " " out "${out}")
if(result EQUAL 0 OR NOT out MATCHES "kiln::runtime is a static C\\+\\+ library: enable C\\+\\+")
  message(FATAL_ERROR "package test: a C-only project should get find_package(kiln)'s "
    "explanation, got (${result}): ${out}")
endif()
message(STATUS "C-only project refused with the explanation: ok")

# --- 3. pkg-config ---------------------------------------------------------------------------
if(NOT KILN_PKG_CONFIG)
  find_program(KILN_PKG_CONFIG NAMES pkg-config pkgconf)
endif()
if(NOT KILN_PKG_CONFIG)
  message(FATAL_ERROR "package test: pkg-config not found (install pkg-config)")
endif()
set(pc_env ${CMAKE_COMMAND} -E env PKG_CONFIG_PATH=${prefix}/${KILN_LIBDIR}/pkgconfig)
step("pkg-config --modversion" ${pc_env} ${KILN_PKG_CONFIG} --modversion kiln-runtime)
string(STRIP "${step_output}" pc_version)
if(NOT pc_version STREQUAL KILN_VERSION)
  message(FATAL_ERROR "package test: kiln-runtime.pc says version ${pc_version}, not ${KILN_VERSION}")
endif()
step("pkg-config --cflags --libs" ${pc_env} ${KILN_PKG_CONFIG} --cflags --libs kiln-runtime)
string(STRIP "${step_output}" pc_flags)
message(STATUS "  ${pc_flags}")
separate_arguments(pc_flags UNIX_COMMAND "${pc_flags}")
set(pc_dir ${KILN_WORK_DIR}/pkg-config)
file(MAKE_DIRECTORY ${pc_dir})
# The C compiler, not the C++ driver, links: the .pc must name the C++ runtime itself.
step("pkg-config: compile and link consumer_c.c with ${KILN_C_COMPILER}"
     ${KILN_C_COMPILER} -std=c99 -Wall -Wextra -Wpedantic -Werror
     "-DKILN_EXPECTED_VERSION=\"${KILN_VERSION}\"" ${consumer_source}/consumer_c.c
     -o ${pc_dir}/consumer_c ${pc_flags})
step("pkg-config: run consumer_c" ${pc_dir}/consumer_c ${pc_dir})

# --- 4. add_subdirectory ---------------------------------------------------------------------
consumer(subdirectory -DKILN_RUNTIME_SOURCE_DIR=${runtime_source})

file(REMOVE_RECURSE ${KILN_WORK_DIR})
message(STATUS "package test: all steps passed")
