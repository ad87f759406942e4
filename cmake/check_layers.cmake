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

# A kind may be made of parts: sub-folders of src/kinds/<k>/, in order, each resting on those
# before it. A file in a part may include its own part and the parts before it; the files at the
# kind's top (its job and registration) may include any part; no part includes them, and every
# sub-folder of such a kind is one of its parts.
#
#   kinds/atmosphere: model (spec, config, physical model, scene points)
#                     → shader (the textures on the host, shipped GLSL, previews)
#                     → bake (passes, double reference, the bake's textures)
#                     → truth (path-traced truth, scene check)
#                     → search (sizes: auto, spectrum: auto)
set(kind_parts_atmosphere model shader bake truth search)

# The line of `text` (the include line as file(STRINGS) read it) in src/<file>.
function(line_of file text out)
  file(READ ${ROOT}/src/${file} content)
  string(FIND "${content}" "${text}" pos)
  set(n 0)
  if(pos GREATER 0)
    string(SUBSTRING "${content}" 0 ${pos} before)
    string(REGEX MATCHALL "\n" newlines "${before}")
    list(LENGTH newlines n)
  endif()
  math(EXPR n "${n} + 1")
  set(${out} ${n} PARENT_SCOPE)
endfunction()

file(GLOB_RECURSE files RELATIVE ${ROOT}/src ${ROOT}/src/*.cpp ${ROOT}/src/*.hpp ${ROOT}/src/*.inc ${ROOT}/src/*.in)
set(errors "")
foreach(f IN LISTS files)
  string(REPLACE "/" ";" parts "${f}")
  list(LENGTH parts depth)
  list(GET parts 0 layer)
  set(own_kind "")
  set(own_part "")  # a kind's file: its part, or empty at the kind's top
  if(layer STREQUAL "kinds")
    list(GET parts 1 own_kind)
    if(depth GREATER 3 AND DEFINED kind_parts_${own_kind})
      list(GET parts 2 own_part)
      list(FIND kind_parts_${own_kind} ${own_part} own_index)
      if(own_index EQUAL -1)
        list(JOIN kind_parts_${own_kind} " " known)
        string(APPEND errors "src/${f}: folder '${own_part}' is not a part of kinds/${own_kind} "
                             "(kind_parts_${own_kind} in cmake/check_layers.cmake: ${known})\n")
        continue()
      endif()
    endif()
  endif()
  if(NOT DEFINED allowed_${layer})
    string(APPEND errors "src/${f}: folder '${layer}' is not in the layer list of cmake/check_layers.cmake\n")
    continue()
  endif()
  file(STRINGS ${ROOT}/src/${f} lines REGEX "^[ \t]*#[ \t]*include[ \t]*\"")
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
        if(NOT own_part STREQUAL "")
          # a part includes its own part or one before it, never the kind's top
          set(inc_part "")
          if(n GREATER 3)
            list(GET iparts 2 inc_part)
          endif()
          list(FIND kind_parts_${own_kind} "${inc_part}" inc_index)
          if(inc_index EQUAL -1 OR inc_index GREATER own_index)
            line_of(${f} "${line}" at)
            list(SUBLIST kind_parts_${own_kind} 0 ${own_index} below)
            list(APPEND below ${own_part})
            list(JOIN below " " below)
            string(APPEND errors "src/${f}:${at}: includes \"${inc}\": part '${own_part}' of kinds/${own_kind} "
                                 "may include only its own part and those before it: ${below}\n")
          endif()
        endif()
        continue()
      endif()
      if(target STREQUAL own_kind)  # kernels/<own kind>/...
        continue()
      endif()
    endif()
    list(FIND src_folders ${target} is_src)
    list(FIND allowed_${layer} ${target} ok)
    if(ok EQUAL -1 AND (NOT is_src EQUAL -1 OR layer STREQUAL "kinds"))
      line_of(${f} "${line}" at)
      list(JOIN allowed_${layer} " " allowed)
      if(allowed STREQUAL "")
        set(allowed "(nothing)")
      endif()
      string(APPEND errors "src/${f}:${at}: includes \"${inc}\": '${layer}/${own_kind}' may include only: ${allowed}\n")
    endif()
  endforeach()
endforeach()
if(errors)
  # one line each, unwrapped (a FATAL_ERROR's text is wrapped), then the error
  message(NOTICE "${errors}")
  message(FATAL_ERROR "includes that go up a layer or across kinds (above)")
endif()
