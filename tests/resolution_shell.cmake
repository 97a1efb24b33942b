# ctest of palpate-resolution --shell (tests/CMakeLists.txt), the lines scripts/make_mesh.sh
# --scene reads. A body with a box (the lump's mesh of the block) gives its box and the focus
# at the centre of its top face; a mesh body without a box (the dome: any shape) gives neither,
# not the default box it does not use, nor a focus derived from that box; its focus appears
# when the scene gives one.
# usage: cmake -DRESOLUTION=path/to/palpate-resolution -DSOURCE_DIR=... -P resolution_shell.cmake
function(shell_lines scene out)
  execute_process(COMMAND ${RESOLUTION} --scene ${SOURCE_DIR}/scenes/${scene} --shell ${ARGN}
                  OUTPUT_VARIABLE text ERROR_VARIABLE err RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "palpate-resolution --scene ${scene} --shell ${ARGN} exited with ${rc}:\n${err}\n${text}")
  endif()
  set(${out} "${text}" PARENT_SCOPE)
endfunction()
function(expect text regex what)
  if(NOT text MATCHES "${regex}")
    message(FATAL_ERROR "${what}: no line matching '${regex}' in\n${text}")
  endif()
endfunction()
function(refuse text regex what)
  if(text MATCHES "${regex}")
    message(FATAL_ERROR "${what}: a line matching '${regex}' in\n${text}")
  endif()
endfunction()

shell_lines(palpation_lump.json lump)
expect("${lump}" "(^|\n)box='-0.05[0-9]* -0.05[0-9]* -0.05[0-9]* 0.05[0-9]* 0.05[0-9]* 0'\n" "the lump (a box)")
expect("${lump}" "(^|\n)focus='0 0 0'\n" "the lump (a box)")
expect("${lump}" "(^|\n)focus_size=[0-9.e-]+\n" "the lump (a box)")
expect("${lump}" "(^|\n)refine_count=1\n" "the lump (a box)")

shell_lines(palpation_dome.json dome)
refuse("${dome}" "(^|\n)box=" "the dome (no box)")
refuse("${dome}" "(^|\n)focus=" "the dome (no box, no focus given)")
expect("${dome}" "(^|\n)focus_size=[0-9.e-]+\n" "the dome")
expect("${dome}" "(^|\n)refine_0='0 0 0.032[0-9]* 0.007[0-9]* [0-9.e-]+'\n" "the dome")

shell_lines(palpation_dome.json focused --set "body.distribution.focus=[0,0,0.05]")
refuse("${focused}" "(^|\n)box=" "the dome with a focus (no box)")
expect("${focused}" "(^|\n)focus='0 0 0.05[0-9]*'\n" "the dome with a focus")
message(STATUS "palpate-resolution --shell: the lump's box and focus; the dome's neither, its focus when given")
