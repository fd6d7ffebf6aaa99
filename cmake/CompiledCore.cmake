# collres_ros/core/_native: the compiled contact core (see src/).
#
# Built by the same CMakeLists.txt for both set-up paths:
# * pip (cmake/build_interfaces.py): coal's PyPI wheel is a cmeel wheel whose CMake
#   package, headers and libraries live in site-packages/cmeel.prefix; that prefix is
#   derived from the `cmeel` package and added to CMAKE_PREFIX_PATH, and pybind11's
#   CMake dir from the `pybind11` package. Eigen's headers come from cmeel-eigen.
# * colcon on a ROS 2 install: ros-jazzy-coal and pybind11_vendor provide both packages
#   (`import cmeel` / `import pybind11` fail there and those steps are skipped).

if(NOT CMAKE_BUILD_TYPE AND NOT CMAKE_CONFIGURATION_TYPES)
  set(CMAKE_BUILD_TYPE Release CACHE STRING "Build type" FORCE)
endif()

# Python3 (Interpreter, Development) is already found by RepairImportedIncludeDirs.cmake.
function(collres_prefix_from_python name code)
  execute_process(COMMAND "${Python3_EXECUTABLE}" -c "${code}"
    OUTPUT_VARIABLE _dir OUTPUT_STRIP_TRAILING_WHITESPACE RESULT_VARIABLE _failed ERROR_QUIET)
  if(NOT _failed AND IS_DIRECTORY "${_dir}")
    message(STATUS "collres_ros: ${name} from ${_dir}")
    set(CMAKE_PREFIX_PATH ${CMAKE_PREFIX_PATH} "${_dir}" PARENT_SCOPE)
  endif()
endfunction()
collres_prefix_from_python(cmeel.prefix
  "import cmeel, os; print(os.path.join(os.path.dirname(os.path.dirname(cmeel.__file__)), 'cmeel.prefix'))")
collres_prefix_from_python(pybind11 "import pybind11; print(pybind11.get_cmake_dir())")

find_package(coal CONFIG REQUIRED)
find_package(pybind11_vendor QUIET)       # ROS: makes pybind11's CMake package findable
set(PYBIND11_FINDPYTHON ON)
find_package(pybind11 CONFIG REQUIRED)

file(GLOB COLLRES_NATIVE_SOURCES CONFIGURE_DEPENDS "${CMAKE_CURRENT_SOURCE_DIR}/src/*.cpp")
pybind11_add_module(_native MODULE ${COLLRES_NATIVE_SOURCES})
target_include_directories(_native PRIVATE "${CMAKE_CURRENT_SOURCE_DIR}/src")
find_package(Threads REQUIRED)           # the solver's second thread (src/worker.h)
target_link_libraries(_native PRIVATE coal::coal Threads::Threads)
target_compile_features(_native PRIVATE cxx_std_17)
# No -march=native: Eigen fixed-size types cross libcoal's ABI (built for generic x86-64).
# -ffp-contract=off: no fused multiply-add where a target has one (aarch64): the solver's
# lanes and its one-by-one path do the same arithmetic, so the same bits on every target.
# -fno-math-errno: std::sqrt as the one instruction (nothing reads errno), so the lanes'
# square roots vectorise (correctly rounded either way: the same bits).
target_compile_options(_native PRIVATE
  $<$<CXX_COMPILER_ID:GNU,Clang>:-Wall -Wextra -Wno-psabi -ffp-contract=off -fno-math-errno>)
# Installed as site-packages/collres_ros/core/_native*.so: $ORIGIN/../.. is site-packages,
# where a pip install keeps coal's cmeel.prefix/lib; coal's own library directory (an
# absolute cmeel.prefix/lib, or the ROS prefix's lib) covers editable and colcon installs.
# libcoal.so finds its Boost, assimp, octomap and qhull through its own RUNPATH.
get_target_property(_coal_library coal::coal IMPORTED_LOCATION_RELEASE)
if(NOT _coal_library)
  get_target_property(_coal_library coal::coal LOCATION)
endif()
get_filename_component(_coal_library_dir "${_coal_library}" DIRECTORY)
set_target_properties(_native PROPERTIES
  INSTALL_RPATH "$ORIGIN/../../cmeel.prefix/lib;${_coal_library_dir}")
if(NOT PYTHON_INSTALL_DIR)
  set(PYTHON_INSTALL_DIR "lib/python${Python3_VERSION_MAJOR}.${Python3_VERSION_MINOR}/site-packages")
endif()
install(TARGETS _native LIBRARY DESTINATION "${PYTHON_INSTALL_DIR}/collres_ros/core")
