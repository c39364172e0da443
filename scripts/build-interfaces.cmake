# Included after each package's project() by build-interfaces.sh (CMAKE_PROJECT_INCLUDE):
# at the end of the package's CMakeLists.txt, drop the include directories the PyPI wheels
# export from the machine that built them (/opt/python/...), which CMake's generate step
# rejects. So packages build unchanged.
set(_roslibpy_lite_wheel_fix "${CMAKE_CURRENT_LIST_DIR}/../msgs/interfaces/wheel_include_dirs.cmake")
cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL include "${_roslibpy_lite_wheel_fix}")
