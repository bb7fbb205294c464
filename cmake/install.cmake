# `cmake --install build [--prefix P]`: the static library, the public headers, the CLI and the
# CMake package (slimrtConfig.cmake, its version file and the exported target slimrt::slimrt), so
# that a consumer project builds with
#   find_package(slimrt REQUIRED)
#   target_link_libraries(app PRIVATE slimrt::slimrt)
# The library is static: the package also finds what it links (TBB, zlib, liblzma, tinyexr, GLU,
# stb), see cmake/slimrtConfig.cmake.in. tests/consumer/ is such a project, built by the ctest
# `install_consumer` against an install into a temporary prefix.
include(CMakePackageConfigHelpers)
set(SLIM_CMAKE_INSTALL_DIR "${CMAKE_INSTALL_LIBDIR}/cmake/slimrt")

install(TARGETS slimrt EXPORT slimrtTargets
  ARCHIVE DESTINATION "${CMAKE_INSTALL_LIBDIR}"
  INCLUDES DESTINATION "${CMAKE_INSTALL_INCLUDEDIR}")
install(TARGETS slimrt-cli RUNTIME DESTINATION "${CMAKE_INSTALL_BINDIR}")
install(DIRECTORY include/slimrt DESTINATION "${CMAKE_INSTALL_INCLUDEDIR}")
install(EXPORT slimrtTargets NAMESPACE slimrt:: DESTINATION "${SLIM_CMAKE_INSTALL_DIR}")

configure_package_config_file(cmake/slimrtConfig.cmake.in
  "${CMAKE_BINARY_DIR}/slimrtConfig.cmake" INSTALL_DESTINATION "${SLIM_CMAKE_INSTALL_DIR}")
write_basic_package_version_file("${CMAKE_BINARY_DIR}/slimrtConfigVersion.cmake"
  VERSION "${PROJECT_VERSION}" COMPATIBILITY SameMinorVersion)
install(FILES "${CMAKE_BINARY_DIR}/slimrtConfig.cmake" "${CMAKE_BINARY_DIR}/slimrtConfigVersion.cmake"
  DESTINATION "${SLIM_CMAKE_INSTALL_DIR}")

# The consumer test: install into a fresh prefix, configure, build and run tests/consumer. Not in
# sanitizer builds: the installed library would need the consumer to link the sanitizer runtime.
if(SLIM_SANITIZE OR SLIM_TSAN)
  return()
endif()
add_test(NAME install_consumer
  COMMAND ${CMAKE_COMMAND} -DBUILD_DIR=${CMAKE_BINARY_DIR} -DSOURCE_DIR=${CMAKE_SOURCE_DIR}
          -DCXX=${CMAKE_CXX_COMPILER} -DPYTHON=${SLIM_PYTHON_EXECUTABLE} -P ${CMAKE_SOURCE_DIR}/cmake/consumer_test.cmake)
set_tests_properties(install_consumer PROPERTIES TIMEOUT 600)
