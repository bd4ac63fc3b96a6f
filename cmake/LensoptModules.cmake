# lensopt_add_module(<folder> [PUBLIC deps...] [PRIVATE deps...])
#
# One library per module folder: lensopt_<folder> from every .cpp under src/<folder>/ (globbed,
# so a new file is picked up), a STATIC library, or an INTERFACE one while the folder has no
# sources (paraxial/ is header-only). Its public headers are include/lensopt/<folder>/; its
# internal headers sit beside its sources and are included as "<folder>/name.h" (src/ is a
# PRIVATE include directory, not installed). The module is appended to LENSOPT_MODULES, the list
# the executable, the tests, the Python package and the install rules use.
function(lensopt_add_module folder)
  cmake_parse_arguments(ARG "" "" "PUBLIC;PRIVATE" ${ARGN})
  set(target lensopt_${folder})
  file(GLOB_RECURSE sources CONFIGURE_DEPENDS ${PROJECT_SOURCE_DIR}/src/${folder}/*.cpp)
  if(sources)
    add_library(${target} STATIC ${sources})
    target_include_directories(${target}
      PUBLIC $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}/include>
             $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>
      PRIVATE ${PROJECT_SOURCE_DIR}/src)
    target_compile_options(${target} PRIVATE -Wall -Wextra)
    target_link_libraries(${target} PUBLIC ${ARG_PUBLIC} PRIVATE ${ARG_PRIVATE})
    # One precompiled header for all modules (CMakeLists.txt LENSOPT_PCH): made by the first,
    # core, reused by the others.
    if(LENSOPT_PCH)
      if(folder STREQUAL "core")
        target_precompile_headers(${target} PRIVATE ${LENSOPT_PCH_HEADERS})
      else()
        target_precompile_headers(${target} REUSE_FROM lensopt_core)
      endif()
    endif()
    # The #include layering is checked before any module compiles.
    if(TARGET lensopt_layering)
      add_dependencies(${target} lensopt_layering)
    endif()
  else()
    add_library(${target} INTERFACE)
    target_include_directories(${target}
      INTERFACE $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}/include>
                $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
    target_link_libraries(${target} INTERFACE ${ARG_PUBLIC})
  endif()
  set_target_properties(${target} PROPERTIES EXPORT_NAME ${folder})
  add_library(lensopt::${folder} ALIAS ${target})
  set(LENSOPT_MODULES ${LENSOPT_MODULES} ${target} PARENT_SCOPE)
endfunction()

# Removes the sources whose path matches `regex` from a module library.
function(lensopt_exclude_sources target regex)
  get_target_property(sources ${target} SOURCES)
  list(FILTER sources EXCLUDE REGEX "${regex}")
  set_property(TARGET ${target} PROPERTY SOURCES ${sources})
endfunction()
