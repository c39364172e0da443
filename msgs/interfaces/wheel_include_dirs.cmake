# The PyPI wheels export include directories of the machine that built them
# (/opt/python/...); CMake's generate step rejects missing paths, so drop them.
get_property(_targets DIRECTORY PROPERTY IMPORTED_TARGETS)
foreach(_t IN LISTS _targets)
  get_target_property(_dirs ${_t} INTERFACE_INCLUDE_DIRECTORIES)
  if(_dirs)
    list(FILTER _dirs EXCLUDE REGEX "^/opt/python/")
    set_target_properties(${_t} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_dirs}")
  endif()
endforeach()
