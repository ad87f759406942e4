# Checks that every #include in src/ goes down the layers (cmake -DROOT=<repo> -P check_layers.cmake).
# A folder may include its own files and those of the folders listed for it; kinds never
# include each other; anything else is an error naming the file, line and include.
#
#   cli       → runner registry job kinds media cl io core
#   runner    → registry job cl io core
#   registry  → kinds/* job core
#   kinds/<k> → job media cl io core, and kernels/common or kernels/<k> (the maths it shares)
#   job       → cl io core
#   media     → core
#   cl, io    → core
#   core      → (nothing)
set(allowed_cli runner registry job kinds media cl io core)
set(allowed_runner registry job cl io core)
set(allowed_registry kinds job core)
set(allowed_kinds job media cl io core common)
set(allowed_job cl io core)
set(allowed_media core)
set(allowed_cl core)
set(allowed_io core)
set(allowed_core "")
set(src_folders cli runner registry kinds job media cl io core)

file(GLOB_RECURSE files RELATIVE ${ROOT}/src ${ROOT}/src/*.cpp ${ROOT}/src/*.hpp ${ROOT}/src/*.inc ${ROOT}/src/*.in)
set(errors "")
foreach(f IN LISTS files)
  string(REPLACE "/" ";" parts "${f}")
  list(GET parts 0 layer)
  set(own_kind "")
  if(layer STREQUAL "kinds")
    list(GET parts 1 own_kind)
  endif()
  if(NOT DEFINED allowed_${layer})
    string(APPEND errors "src/${f}: folder '${layer}' is not in the layer list of cmake/check_layers.cmake\n")
    continue()
  endif()
  file(STRINGS ${ROOT}/src/${f} lines REGEX "^[ \t]*#[ \t]*include[ \t]*\"")
  file(STRINGS ${ROOT}/src/${f} all_lines)
  foreach(line IN LISTS lines)
    string(REGEX REPLACE "^[ \t]*#[ \t]*include[ \t]*\"([^\"]+)\".*" "\\1" inc "${line}")
    string(REPLACE "/" ";" iparts "${inc}")
    list(LENGTH iparts n)
    if(n LESS 2)
      continue()  # a file beside it
    endif()
    list(GET iparts 0 target)
    if(target STREQUAL layer AND NOT layer STREQUAL "kinds")
      continue()
    endif()
    if(layer STREQUAL "kinds")
      list(GET iparts 1 target_kind)
      if(target STREQUAL "kinds" AND target_kind STREQUAL own_kind)
        continue()
      endif()
      if(target STREQUAL own_kind)  # kernels/<own kind>/...
        continue()
      endif()
    endif()
    list(FIND src_folders ${target} is_src)
    list(FIND allowed_${layer} ${target} ok)
    if(ok EQUAL -1 AND (NOT is_src EQUAL -1 OR layer STREQUAL "kinds"))
      string(APPEND errors "src/${f}: includes \"${inc}\": '${layer}/${own_kind}' may include only: ${allowed_${layer}}\n")
    endif()
  endforeach()
endforeach()
if(errors)
  message(FATAL_ERROR "includes that go up a layer or across kinds:\n${errors}")
endif()
