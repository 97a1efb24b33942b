# The direction of the dependencies between the project's folders, checked on the
# includes of every source (ctest: dependency_direction). The CMake targets link the
# same way (CMakeLists.txt); this catches an include the link graph would let pass
# (every target has the source root on its include path).
#
#   core <- analysis <- tools          protocol <- server, clients <- bench (bench: the session thread too)
#   cli: the programs' small helpers (header only: arguments, statistics, text files, child
#   processes), includable from every program and test
#   examples: the user guide's programs (docs/guide/), a user's view: the core, the protocol,
#   the clients' connection; examples/embed_core.cpp the core alone (no networking)
#
# Run: cmake -DSOURCE_DIR=<repo> -P tests/dependency_direction.cmake
cmake_minimum_required(VERSION 3.25)
if(NOT SOURCE_DIR)
  message(FATAL_ERROR "usage: cmake -DSOURCE_DIR=<repository> -P dependency_direction.cmake")
endif()

# Project folders each folder may include (besides itself).
set(allowed_core "")
set(allowed_analysis "core")
set(allowed_cli "")
set(allowed_protocol "core")  # scene_wire: wire scenes through core's scene reader
set(allowed_server "core;protocol;cli")
set(allowed_clients "core;protocol;cli")
set(allowed_tools "core;analysis;cli")
set(allowed_bench "core;analysis;protocol;cli;tools;clients;server")  # clients: the haptic library; server: its session thread (multirate study)
set(allowed_examples "core;protocol;clients;cli")
set(project_folders core analysis cli protocol server clients tools bench tests fuzz examples)
# Files held to less than their folder: the embedding example shows the core alone.
set(allowed_file_examples/embed_core.cpp "core")

# System headers a folder must not include: the real-time core has no networking,
# threads (but its worker pool's and its refocus worker's) or sparse direct solver (but the model build's); the local
# tools and the analysis no networking; the networked programs no solver.
set(forbidden_core "capnp/;kj/;cholmod;Eigen/CholmodSupport;thread>;mutex>;condition_variable>")
# ... but for the two places that own threads: the force loops' worker pool (issue #17,
# integrator.threads) and the refocus worker of a cloud that follows the tool (issue #32,
# refocus.h, lock-free: atomics only), which may include <thread>.
set(exempt_core_thread_pool "core/thread_pool.h;core/thread_pool.cpp;core/refocus.h")
# ... and for the one solve of the model build: the consistent-integration correction's
# constraint system (a supernodal Cholesky; never called by a step).
set(exempt_core_cholmod "core/consistent_integration.cpp")
set(forbidden_analysis "capnp/;kj/")
set(forbidden_tools "capnp/;kj/")
set(forbidden_protocol "cholmod;Eigen/CholmodSupport")
set(forbidden_server "cholmod;Eigen/CholmodSupport")
set(forbidden_clients "cholmod;Eigen/CholmodSupport")
set(forbidden_examples "cholmod;Eigen/CholmodSupport")
set(forbidden_file_examples/embed_core.cpp "capnp/;kj/")

set(violations "")
foreach(folder core analysis cli protocol server clients tools bench examples)
  file(GLOB_RECURSE sources "${SOURCE_DIR}/${folder}/*.h" "${SOURCE_DIR}/${folder}/*.cpp")
  foreach(source ${sources})
    file(STRINGS "${source}" includes REGEX "^[ \t]*#[ \t]*include")
    file(RELATIVE_PATH name "${SOURCE_DIR}" "${source}")
    set(allowed "${allowed_${folder}}")
    set(scope "${folder}/")
    if(DEFINED allowed_file_${name})
      set(allowed "${allowed_file_${name}}")
      set(scope "${name}")
    endif()
    foreach(line ${includes})
      if(line MATCHES "#[ \t]*include[ \t]*\"([a-z_]+)/")
        set(target "${CMAKE_MATCH_1}")
        if(NOT target STREQUAL folder AND target IN_LIST project_folders AND NOT target IN_LIST allowed)
          string(APPEND violations "  ${name}: ${line}   (${scope} may include: ${folder} ${allowed})\n")
        endif()
      endif()
      foreach(banned ${forbidden_${folder}} ${forbidden_file_${name}})
        string(FIND "${line}" "${banned}" at)
        if(at GREATER -1 AND banned STREQUAL "thread>" AND name IN_LIST exempt_core_thread_pool)
          set(at -1)
        endif()
        if(at GREATER -1 AND banned STREQUAL "Eigen/CholmodSupport" AND name IN_LIST exempt_core_cholmod)
          set(at -1)
        endif()
        if(at GREATER -1)
          string(APPEND violations "  ${name}: ${line}   (${scope} must not include ${banned})\n")
        endif()
      endforeach()
    endforeach()
  endforeach()
endforeach()

if(violations)
  message(FATAL_ERROR "includes against the dependency direction:\n${violations}")
endif()
message(STATUS "dependency direction: every include of core, analysis, cli, protocol, server, clients, tools, bench and examples agrees")
