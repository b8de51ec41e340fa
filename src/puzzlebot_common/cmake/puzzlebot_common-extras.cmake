# CMake helpers of the PuzzleBot workspace (catkin CFG_EXTRAS of puzzlebot_common; a package gets them
# with find_package(catkin REQUIRED COMPONENTS puzzlebot_common)).
#
# puzzlebot_install_python(PROGRAMS file... DESTINATION dir)
#   catkin_install_python, then, at install time, the installed scripts' first line becomes
#   "#!<PYTHON_EXECUTABLE>": the interpreter the workspace was built with (scripts/setup.sh: .venv's, on
#   /usr/bin/python3 with casadi and pybullet). catkin_install_python rewrites only "#!/usr/bin/env python"
#   and keeps "env", so an installed node would start with whatever python3 is first on PATH (README:
#   the pyenv trap). The devel space's wrappers already carry PYTHON_EXECUTABLE.
function(puzzlebot_install_python)
  catkin_install_python(${ARGN})
  cmake_parse_arguments(ARG "OPTIONAL" "DESTINATION" "PROGRAMS" ${ARGN})
  foreach(program ${ARG_PROGRAMS})
    get_filename_component(name "${program}" NAME)
    install(CODE "
      set(_script \"\$ENV{DESTDIR}\${CMAKE_INSTALL_PREFIX}/${ARG_DESTINATION}/${name}\")
      file(READ \"\${_script}\" _text)
      string(REGEX REPLACE \"^#![^\\n]*\" \"#!${PYTHON_EXECUTABLE}\" _text \"\${_text}\")
      file(WRITE \"\${_script}\" \"\${_text}\")
    ")
  endforeach()
endfunction()

# puzzlebot_add_rostests([PROGRAMS file...] TESTS file.test...)
#   With CATKIN_ENABLE_TESTING: the rostests' scripts installed as the nodes are (puzzlebot_install_python
#   to the package's bin destination, where rostest finds them, with the workspace's interpreter) and each
#   .test file registered (add_rostest). Without it, nothing. A macro, so that find_package(rostest)
#   defines add_rostest and its variables in the calling package's scope.
macro(puzzlebot_add_rostests)
  cmake_parse_arguments(_puzzlebot_rostests "" "" "PROGRAMS;TESTS" ${ARGN})
  if(CATKIN_ENABLE_TESTING)
    find_package(rostest REQUIRED)
    if(_puzzlebot_rostests_PROGRAMS)
      puzzlebot_install_python(PROGRAMS ${_puzzlebot_rostests_PROGRAMS}
                               DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})
    endif()
    foreach(_puzzlebot_rostest ${_puzzlebot_rostests_TESTS})
      add_rostest(${_puzzlebot_rostest})
    endforeach()
  endif()
endmacro()
