# The Python module `slimrt` (python/slimrt_module.cpp), built with pybind11 for Debian's
# interpreter /usr/bin/python3 unless SLIM_PYTHON_EXECUTABLE names another one (the first
# python3 on PATH may be a different installation without Debian's numpy and pybind11).
# The module lands in ${CMAKE_BINARY_DIR}/python (PYTHONPATH=build/python imports it) and
# `cmake --install` puts it in SLIM_PYTHON_INSTALL_DIR.
# Not in sanitizer or fuzz builds: an instrumented module only loads with the sanitizer runtime
# preloaded into the interpreter.
if(NOT SLIM_PYTHON OR SLIM_SANITIZE OR SLIM_TSAN OR SLIM_FUZZ)
  return()
endif()
set(SLIM_PYTHON_EXECUTABLE "/usr/bin/python3" CACHE FILEPATH "Python interpreter of the module")
set(Python_EXECUTABLE "${SLIM_PYTHON_EXECUTABLE}")
set(PYTHON_EXECUTABLE "${SLIM_PYTHON_EXECUTABLE}")
set(PYBIND11_FINDPYTHON ON)
find_package(Python COMPONENTS Interpreter Development.Module QUIET)
find_package(pybind11 CONFIG QUIET)
if(NOT Python_FOUND OR NOT pybind11_FOUND)
  message(WARNING "SLIM_PYTHON: no pybind11 or Python development files for "
                  "${SLIM_PYTHON_EXECUTABLE} (Debian: pybind11-dev python3-dev); the Python "
                  "module is not built")
  return()
endif()
pybind11_add_module(slimrt_python MODULE python/slimrt_module.cpp)
set_target_properties(slimrt_python PROPERTIES OUTPUT_NAME slimrt
  LIBRARY_OUTPUT_DIRECTORY "${CMAKE_BINARY_DIR}/python")
target_compile_options(slimrt_python PRIVATE ${SLIM_WARN})
target_compile_definitions(slimrt_python PRIVATE SLIMRT_VERSION="${PROJECT_VERSION}")
target_link_libraries(slimrt_python PRIVATE slimrt)
# Debian's interpreter searches lib/python3/dist-packages under /usr/local (and /usr).
set(SLIM_PYTHON_INSTALL_DIR "lib/python3/dist-packages" CACHE STRING
  "Install folder of the Python module, relative to CMAKE_INSTALL_PREFIX")
install(TARGETS slimrt_python LIBRARY DESTINATION "${SLIM_PYTHON_INSTALL_DIR}" COMPONENT python)
