# ctest of palpate-stable-dt on a scene with a free tool (tests/CMakeLists.txt): the dome
# (scenes/palpation_dome.json, guide "free") must give a stable step, measured with the tool
# held on a vertical guide and saying so. A pushed free tool slides off the dome at every dt in
# a 1 s trial (issue #35: the tool found no stable step at all; --set indenter.guide=free still
# shows that, in about 20 s, too long for this test).
# usage: cmake -DSTABLE_DT=path/to/palpate-stable-dt -DSOURCE_DIR=... -P stable_dt_free_tool.cmake
set(scene ${SOURCE_DIR}/scenes/palpation_dome.json)
execute_process(COMMAND ${STABLE_DT} --scene ${scene} --json --quiet --tolerance 0.05
                OUTPUT_VARIABLE out ERROR_VARIABLE err RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "palpate-stable-dt on the dome exited with ${rc}:\n${err}\n${out}")
endif()
string(JSON guided GET "${out}" tool_guided_for_measurement)
string(JSON guide GET "${out}" tool_guide)
string(JSON dt GET "${out}" dt_max_stable_s)
if(NOT guided OR NOT guide STREQUAL "vertical")
  message(FATAL_ERROR "the free tool was not guided for the measurement: ${out}")
endif()
# The scene runs at 1 ms; the measured limit is about 2.5 ms (symplectic Euler).
if(NOT dt GREATER 0.001 OR dt GREATER 0.01)
  message(FATAL_ERROR "dt_max_stable_s = ${dt}, expected between the scene's 1 ms and 10 ms")
endif()
message(STATUS "dome, free tool guided for the measurement: dt_max_stable = ${dt} s")
