# ctest install_consumer (cmake -P): installs the build tree into a fresh prefix, then
# configures, builds and runs tests/consumer, a project that only knows find_package(slimrt).
#   -DBUILD_DIR=<slimrt build tree> -DSOURCE_DIR=<slimrt source> -DCXX=<compiler>
set(work "${BUILD_DIR}/consumer-test")
file(REMOVE_RECURSE "${work}")
set(prefix "${work}/prefix")

function(run what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${what} failed (${rc}):\n${out}\n${err}")
  endif()
  message(STATUS "${what}: ok")
  set(last_output "${out}" PARENT_SCOPE)
endfunction()

run("install" ${CMAKE_COMMAND} --install "${BUILD_DIR}" --prefix "${prefix}")
foreach(f include/slimrt/slimrt.h bin/slimrt lib/cmake/slimrt/slimrtConfig.cmake
          lib/cmake/slimrt/slimrtConfigVersion.cmake)
  if(NOT EXISTS "${prefix}/${f}")
    message(FATAL_ERROR "install: ${prefix}/${f} is missing")
  endif()
endforeach()
run("configure consumer" ${CMAKE_COMMAND} -S "${SOURCE_DIR}/tests/consumer" -B "${work}/build"
    -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=${CXX} "-DCMAKE_PREFIX_PATH=${prefix}")
run("build consumer" ${CMAKE_COMMAND} --build "${work}/build")
run("run consumer" "${work}/build/consumer")
message(STATUS "consumer says: ${last_output}")
if(NOT last_output MATCHES "hit triangle 1 at t = 2")
  message(FATAL_ERROR "consumer: unexpected output '${last_output}'")
endif()
# The installed Python module, when it was built, imports from the prefix alone.
file(GLOB py_module "${prefix}/lib/python3/dist-packages/slimrt*.so")
if(py_module AND PYTHON)
  file(WRITE "${work}/check.py" [=[
import numpy as np
import slimrt
s = slimrt.RaycastingScene()
s.add_triangles(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32),
                np.array([[0, 1, 2]], np.uint32))
print(s.cast_rays(np.array([[0.2, 0.2, 1, 0, 0, -1]], np.float32))["t_hit"][0], slimrt.__file__)
]=])
  run("import installed Python module" ${CMAKE_COMMAND} -E env
      "PYTHONPATH=${prefix}/lib/python3/dist-packages" ${PYTHON} "${work}/check.py")
  message(STATUS "python says: ${last_output}")
  if(NOT last_output MATCHES "^1.0 ${prefix}")
    message(FATAL_ERROR "installed Python module: unexpected output '${last_output}'")
  endif()
endif()
file(REMOVE_RECURSE "${work}")
