# ctest install_consumer (tests/CMakeLists.txt): the core as a package. Installs the build
# tree into a fresh prefix (cmake --install), configures a project of its own outside the
# source tree that finds it with find_package(palpate CONFIG) and links palpate::core, builds
# the guide's embedding example (examples/embed_core.cpp, copied there) with it, and runs it
# on the haptic scene: a program that sees only the installed headers, library and config.
# usage: cmake -DBUILD_DIR=... -DSOURCE_DIR=... -DWORK_DIR=... -DGENERATOR=... -P install_consumer.cmake
file(REMOVE_RECURSE ${WORK_DIR})
set(prefix ${WORK_DIR}/prefix)
set(consumer ${WORK_DIR}/consumer)
function(run what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${what} failed (${rc}):\n${out}\n${err}")
  endif()
  set(last_output "${out}" PARENT_SCOPE)
endfunction()

run("cmake --install" ${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${prefix})
foreach(f include/palpate/core/scene.h include/palpate/core/step.h lib/cmake/palpate/palpateConfig.cmake
          lib/cmake/palpate/palpateConfigVersion.cmake lib/cmake/palpate/palpateTargets.cmake)
  if(NOT EXISTS ${prefix}/${f})
    message(FATAL_ERROR "not installed: ${f}")
  endif()
endforeach()

file(MAKE_DIRECTORY ${consumer}/src)
file(COPY ${SOURCE_DIR}/examples/embed_core.cpp DESTINATION ${consumer}/src)
file(WRITE ${consumer}/src/CMakeLists.txt [=[
cmake_minimum_required(VERSION 3.25)
project(palpate_consumer LANGUAGES CXX)
set(CMAKE_CXX_STANDARD 20)
set(CMAKE_CXX_STANDARD_REQUIRED ON)
find_package(palpate 0.1 CONFIG REQUIRED)
add_executable(embed_core embed_core.cpp)
target_link_libraries(embed_core PRIVATE palpate::core)
]=])
run("configuring the consumer" ${CMAKE_COMMAND} -S ${consumer}/src -B ${consumer}/build -G ${GENERATOR}
    -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_FIND_PACKAGE_PREFER_CONFIG=ON)
run("building the consumer" ${CMAKE_COMMAND} --build ${consumer}/build)
# The headers came from the prefix, not from the source tree.
file(READ ${consumer}/build/CMakeCache.txt cache)
string(FIND "${cache}" "palpate_DIR:PATH=${prefix}/lib/cmake/palpate" at)
if(at EQUAL -1)
  message(FATAL_ERROR "find_package(palpate) did not find the installed package in ${prefix}")
endif()
run("running the consumer" ${consumer}/build/embed_core ${SOURCE_DIR}/scenes/hertz_cube_haptic.json 53.83 300)
if(NOT last_output MATCHES "indentation [0-9.]+ m, contact force")
  message(FATAL_ERROR "unexpected output:\n${last_output}")
endif()
message(STATUS "${last_output}")
