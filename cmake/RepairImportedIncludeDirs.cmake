# Repair INTERFACE_INCLUDE_DIRECTORIES of imported targets that name paths
# which do not exist on this machine (and of our own targets that name paths
# inside the source tree).
#
# The ROS 2 Jazzy wheels on PyPI export `<pkg>::<pkg>__rosidl_generator_py`
# with the wheel build container's Python and NumPy include dirs
# (/opt/python/cp311-cp311/...), which makes CMake's generate step fail.
# At the end of configure, every such non-existent directory of an imported
# target is replaced with this interpreter's Python3 (and NumPy) include dirs.
# On a normal apt ROS install all paths exist and nothing changes.

find_package(Python3 REQUIRED COMPONENTS Interpreter Development NumPy)

function(collres_repair_imported_include_dirs)
  get_property(_dirs GLOBAL PROPERTY COLLRES_SCAN_DIRS)
  set(_replacement ${Python3_INCLUDE_DIRS} ${Python3_NumPy_INCLUDE_DIRS})
  foreach(_dir IN LISTS _dirs)
    get_property(_targets DIRECTORY "${_dir}" PROPERTY IMPORTED_TARGETS)
    foreach(_target IN LISTS _targets)
      get_target_property(_includes ${_target} INTERFACE_INCLUDE_DIRECTORIES)
      if(NOT _includes)
        continue()
      endif()
      set(_fixed "")
      set(_changed FALSE)
      foreach(_inc IN LISTS _includes)
        if(_inc MATCHES "^\\$<" OR EXISTS "${_inc}")
          list(APPEND _fixed "${_inc}")
        else()
          list(APPEND _fixed ${_replacement})
          set(_changed TRUE)
        endif()
      endforeach()
      if(_changed)
        list(REMOVE_DUPLICATES _fixed)
        set_target_properties(${_target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_fixed}")
      endif()
    endforeach()
    # A venv inside the source tree (.venv/) puts the Python and NumPy include dirs
    # under the source dir, which CMake refuses in exported targets: keep them
    # for the build only.
    get_property(_own DIRECTORY "${_dir}" PROPERTY BUILDSYSTEM_TARGETS)
    foreach(_target IN LISTS _own)
      get_target_property(_includes ${_target} INTERFACE_INCLUDE_DIRECTORIES)
      if(NOT _includes)
        continue()
      endif()
      set(_fixed "")
      foreach(_inc IN LISTS _includes)
        string(FIND "${_inc}" "${CMAKE_SOURCE_DIR}/" _pos)
        if(_pos EQUAL 0)
          list(APPEND _fixed "$<BUILD_INTERFACE:${_inc}>")
        else()
          list(APPEND _fixed "${_inc}")
        endif()
      endforeach()
      set_target_properties(${_target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_fixed}")
    endforeach()
  endforeach()
endfunction()

set_property(GLOBAL APPEND PROPERTY COLLRES_SCAN_DIRS "${CMAKE_CURRENT_SOURCE_DIR}")
cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL collres_repair_imported_include_dirs)
