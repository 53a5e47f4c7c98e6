# Install rules of kiln_runtime (included by ../CMakeLists.txt when KILN_RUNTIME_INSTALL is
# ON), all in the component `runtime`:
#   lib/libkiln_runtime.a, include/kiln_runtime.h, include/kiln_lppv.h, include/kiln/*.h
#   (with the generated kiln/version.h), lib/cmake/kiln/ (find_package(kiln): targets
#   kiln::runtime and kiln::base) and lib/pkgconfig/kiln-runtime.pc.
# `cmake --install <build> --component runtime` installs exactly these; tests/package checks
# that a C99 and a C++ program build against them with CMake and with pkg-config.
include(CMakePackageConfigHelpers)

set(KILN_RUNTIME_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/kiln)

install(TARGETS kiln_runtime kiln_base EXPORT kilnTargets
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT runtime)

# The public headers, from the explicit list, each under include/ at its place in the tree.
foreach(header IN LISTS KILN_RUNTIME_PUBLIC_HEADERS)
  if(IS_ABSOLUTE "${header}")
    file(RELATIVE_PATH relative "${KILN_RUNTIME_GENERATED_INCLUDE_DIR}" "${header}")
  else()
    string(REGEX REPLACE "^include/" "" relative "${header}")
  endif()
  get_filename_component(subdir "${relative}" DIRECTORY)
  install(FILES "${header}" DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/${subdir} COMPONENT runtime)
endforeach()

install(EXPORT kilnTargets NAMESPACE kiln:: DESTINATION ${KILN_RUNTIME_CMAKE_DIR}
  COMPONENT runtime)

configure_package_config_file(cmake/kilnConfig.cmake.in
  ${CMAKE_CURRENT_BINARY_DIR}/kilnConfig.cmake
  INSTALL_DESTINATION ${KILN_RUNTIME_CMAKE_DIR})
# Compatibility: kiln is 0.x, where (semantic versioning) a minor release may break the API
# and the .kprobe reader, so find_package(kiln 0.1) must accept 0.1.x but not 0.2:
# SameMinorVersion. From 1.0 on a major release marks a break: SameMajorVersion.
if(KILN_RUNTIME_VERSION_MAJOR EQUAL 0)
  set(_kiln_compatibility SameMinorVersion)
else()
  set(_kiln_compatibility SameMajorVersion)
endif()
write_basic_package_version_file(${CMAKE_CURRENT_BINARY_DIR}/kilnConfigVersion.cmake
  VERSION ${KILN_RUNTIME_VERSION} COMPATIBILITY ${_kiln_compatibility})
install(FILES
  ${CMAKE_CURRENT_BINARY_DIR}/kilnConfig.cmake
  ${CMAKE_CURRENT_BINARY_DIR}/kilnConfigVersion.cmake
  DESTINATION ${KILN_RUNTIME_CMAKE_DIR} COMPONENT runtime)

# pkg-config. The library is static and C++ inside, so Libs carries what a C linker lacks:
# the C++ compiler's implicit link libraries minus the C compiler's (for GCC: stdc++ and m,
# what CMake adds itself when a C program links a C++ static library), and -lm always.
# prefix is found from the .pc file's own place (${pcfiledir}), so the installed tree can be
# moved, and `cmake --install --prefix` gives a correct file without reconfiguring.
set(KILN_PC_LIBS "")
foreach(lib IN LISTS CMAKE_CXX_IMPLICIT_LINK_LIBRARIES ITEMS m)
  if(lib IN_LIST CMAKE_C_IMPLICIT_LINK_LIBRARIES)
    continue()
  endif()
  if(lib MATCHES "^-" OR IS_ABSOLUTE "${lib}")
    set(flag "${lib}")
  else()
    set(flag "-l${lib}")
  endif()
  if(NOT flag IN_LIST KILN_PC_LIBS)
    list(APPEND KILN_PC_LIBS "${flag}")
  endif()
endforeach()
list(JOIN KILN_PC_LIBS " " KILN_PC_LIBS)
if(IS_ABSOLUTE "${CMAKE_INSTALL_LIBDIR}" OR IS_ABSOLUTE "${CMAKE_INSTALL_INCLUDEDIR}")
  set(KILN_PC_PREFIX "${CMAKE_INSTALL_PREFIX}")
  set(KILN_PC_LIBDIR "${CMAKE_INSTALL_FULL_LIBDIR}")
  set(KILN_PC_INCLUDEDIR "${CMAKE_INSTALL_FULL_INCLUDEDIR}")
else()
  file(RELATIVE_PATH _kiln_pc_up "/prefix/${CMAKE_INSTALL_LIBDIR}/pkgconfig" "/prefix")
  string(REGEX REPLACE "/$" "" _kiln_pc_up "${_kiln_pc_up}")
  set(KILN_PC_PREFIX "\${pcfiledir}/${_kiln_pc_up}")
  set(KILN_PC_LIBDIR "\${prefix}/${CMAKE_INSTALL_LIBDIR}")
  set(KILN_PC_INCLUDEDIR "\${prefix}/${CMAKE_INSTALL_INCLUDEDIR}")
endif()
configure_file(cmake/kiln-runtime.pc.in ${CMAKE_CURRENT_BINARY_DIR}/kiln-runtime.pc @ONLY)
install(FILES ${CMAKE_CURRENT_BINARY_DIR}/kiln-runtime.pc
  DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig COMPONENT runtime)
