# libFuzzer targets (fuzz/*.cpp) and the seed generator, for ./fuzz.sh and CI.
#
#   CC=clang-14 CXX=clang++-14 cmake -S . -B build-fuzz -DSLIM_FUZZ=ON -DSLIM_SANITIZE=ON
#   cmake --build build-fuzz --target slimrt_fuzz
#
# SLIM_FUZZ needs clang (Debian's clang-14 ships libFuzzer). The targets but `scene` and
# `scene_file` do not link
# the whole library: each compiles just the sources it exercises (readers, decoders, the pairing)
# with -fsanitize=fuzzer-no-link, so that coverage reaches the header-only tinyobjloader and
# tinygltf they include, and the fuzz build stays short; `scene` links the library, which this
# build tree instruments too. Use it with SLIM_SANITIZE=ON so that memory errors and undefined
# behaviour stop the run (fuzz.sh does).
option(SLIM_FUZZ "Build the libFuzzer targets in fuzz/ (clang only)" OFF)

if(SLIM_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID MATCHES "Clang")
    message(FATAL_ERROR "SLIM_FUZZ=ON needs clang (libFuzzer): configure with CXX=clang++-14")
  endif()

  # The readers (src/io/) and what they call.
  add_library(slimrt_fuzz_io STATIC src/io/obj.cpp src/io/ply.cpp src/io/gltf.cpp src/io/xz.cpp
                                    src/io/byte_window.cpp src/io/output.cpp src/core/error.cpp
                                    src/mesh/polymesh.cpp)
  target_include_directories(slimrt_fuzz_io PUBLIC include src fuzz)
  target_compile_options(slimrt_fuzz_io PRIVATE ${SLIM_WARN} -fsanitize=fuzzer-no-link)
  target_link_libraries(slimrt_fuzz_io PUBLIC LibLZMA::LibLZMA ZLIB::ZLIB
                                              nlohmann_json::nlohmann_json)

  # The seed corpus generator (a plain program).
  add_executable(slimrt_make_seeds fuzz/make_seeds.cpp)
  set_target_properties(slimrt_make_seeds PROPERTIES OUTPUT_NAME make_seeds
                                                     RUNTIME_OUTPUT_DIRECTORY fuzz)
  target_link_libraries(slimrt_make_seeds PRIVATE LibLZMA::LibLZMA)

  add_custom_target(slimrt_fuzz)
  add_dependencies(slimrt_fuzz slimrt_make_seeds)
  # One target per reader and per byte decoder; the name after fuzz_ is its corpus directory.
  # SLIM_FUZZ_SOURCES_<t>: library sources a decoder target compiles besides its own file.
  set(SLIM_FUZZ_TARGETS obj ply gltf glb xz lossy_subgrid quantized_mesh pairing scene cluster
                        scene_file)
  set(SLIM_FUZZ_SOURCES_lossy_subgrid src/prim/lossy_subgrid.cpp)
  set(SLIM_FUZZ_SOURCES_cluster src/prim/cluster.cpp src/bvh/quantize_boxes.cpp)  # the cluster block decoder, the multi-leaf boxes
  set(SLIM_FUZZ_LIBS_cluster TBB::tbb)  # cluster.cpp's quantize runs parallel_for
  set(SLIM_FUZZ_SOURCES_quantized_mesh src/prim/quantized_mesh.cpp src/mesh/tessellate.cpp)
  set(SLIM_FUZZ_LIBS_quantized_mesh ${SLIM_GLU_LIB})
  # pairing: the pairing and the fan triangulation Scene::build runs first, against the test
  # reference (tests/pairing_reference.h) and the edge orders only the tests run
  # (tests/pairing_orders.cpp).
  set(SLIM_FUZZ_SOURCES_pairing src/mesh/pairing.cpp src/mesh/triangulate.cpp
                             tests/pairing_orders.cpp)
  set(SLIM_FUZZ_LIBS_pairing TBB::tbb)
  # scene: every configuration through the public API, so the whole library (built here with
  # coverage instrumentation, unlike in the other build trees).
  set(SLIM_FUZZ_LIBS_scene slimrt)
  # scene_file: Scene::open of arbitrary bytes (the library too); make_seeds writes its seeds,
  # small scene files, with the library.
  set(SLIM_FUZZ_LIBS_scene_file slimrt ${SLIM_XXHASH_LIB})
  target_link_libraries(slimrt_make_seeds PRIVATE slimrt)
  # cluster: its seeds are blocks of the library's cluster encoder (src/prim/cluster.h).
  target_include_directories(slimrt_make_seeds PRIVATE src)
  target_compile_options(slimrt_make_seeds PRIVATE ${SLIM_ISA_FLAGS})
  target_compile_definitions(slimrt_make_seeds PRIVATE ${SLIM_ISA_DEF})
  target_compile_options(slimrt PRIVATE -fsanitize=fuzzer-no-link)
  foreach(t IN LISTS SLIM_FUZZ_TARGETS)
    add_executable(slimrt_fuzz_${t} fuzz/fuzz_${t}.cpp ${SLIM_FUZZ_SOURCES_${t}})
    set_target_properties(slimrt_fuzz_${t} PROPERTIES OUTPUT_NAME fuzz_${t}
                                                       RUNTIME_OUTPUT_DIRECTORY fuzz)
    target_compile_options(slimrt_fuzz_${t} PRIVATE ${SLIM_WARN} ${SLIM_ISA_FLAGS}
                                                    -fsanitize=fuzzer-no-link)
    target_compile_definitions(slimrt_fuzz_${t} PRIVATE ${SLIM_ISA_DEF})
    target_link_options(slimrt_fuzz_${t} PRIVATE -fsanitize=fuzzer)
    target_include_directories(slimrt_fuzz_${t} PRIVATE tests)
    target_link_libraries(slimrt_fuzz_${t} PRIVATE slimrt_fuzz_io ${SLIM_FUZZ_LIBS_${t}})
    add_dependencies(slimrt_fuzz slimrt_fuzz_${t})
  endforeach()
endif()
