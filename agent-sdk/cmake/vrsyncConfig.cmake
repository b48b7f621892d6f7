# CMake package of the vrsync agent SDK, installed by agent-sdk/install.sh.
#
#   find_package(vrsync 0.1 REQUIRED)      # CMAKE_PREFIX_PATH=<prefix> if not in a default place
#   target_link_libraries(my_agent PRIVATE vrsync::agent)          # shared libvrsync_agent.so
#   target_link_libraries(my_agent PRIVATE vrsync::agent_static)   # static libvrsync_agent.a
#
# Both targets carry the include directory (vrsync.h, vrsync/agent.hpp, vrsync/compat.hpp).
# The C++ headers need C++17. Set VRSYNC_PREFER_STATIC=ON before find_package to make
# vrsync::agent the static library.

# <prefix>/lib/cmake/vrsync/vrsyncConfig.cmake -> <prefix>
get_filename_component(_vrsync_prefix "${CMAKE_CURRENT_LIST_DIR}/../../.." ABSOLUTE)
set(_vrsync_libdir "${_vrsync_prefix}/lib")
set(_vrsync_includedir "${_vrsync_prefix}/include")

if(NOT EXISTS "${_vrsync_includedir}/vrsync.h")
  set(vrsync_FOUND FALSE)
  set(vrsync_NOT_FOUND_MESSAGE "vrsync.h not found in ${_vrsync_includedir}")
  return()
endif()

# System libraries the Rust standard library and iceoryx2 need when linking statically.
set(_vrsync_static_deps pthread dl m rt util gcc_s c)

if(NOT TARGET vrsync::agent_shared AND EXISTS "${_vrsync_libdir}/libvrsync_agent.so")
  add_library(vrsync::agent_shared SHARED IMPORTED)
  set_target_properties(vrsync::agent_shared PROPERTIES
    IMPORTED_LOCATION "${_vrsync_libdir}/libvrsync_agent.so"
    # The Rust-built library has no SONAME: link it as -lvrsync_agent, not by its path.
    IMPORTED_NO_SONAME TRUE
    INTERFACE_INCLUDE_DIRECTORIES "${_vrsync_includedir}")
endif()

if(NOT TARGET vrsync::agent_static AND EXISTS "${_vrsync_libdir}/libvrsync_agent.a")
  add_library(vrsync::agent_static STATIC IMPORTED)
  set_target_properties(vrsync::agent_static PROPERTIES
    IMPORTED_LOCATION "${_vrsync_libdir}/libvrsync_agent.a"
    IMPORTED_LINK_INTERFACE_LANGUAGES "C"
    INTERFACE_INCLUDE_DIRECTORIES "${_vrsync_includedir}"
    INTERFACE_LINK_LIBRARIES "${_vrsync_static_deps}")
endif()

if(NOT TARGET vrsync::agent)
  if(VRSYNC_PREFER_STATIC AND TARGET vrsync::agent_static)
    add_library(vrsync::agent ALIAS vrsync::agent_static)
  elseif(TARGET vrsync::agent_shared)
    add_library(vrsync::agent ALIAS vrsync::agent_shared)
  elseif(TARGET vrsync::agent_static)
    add_library(vrsync::agent ALIAS vrsync::agent_static)
  else()
    set(vrsync_FOUND FALSE)
    set(vrsync_NOT_FOUND_MESSAGE "no libvrsync_agent.so or libvrsync_agent.a in ${_vrsync_libdir}")
    return()
  endif()
endif()

set(vrsync_INCLUDE_DIRS "${_vrsync_includedir}")
set(vrsync_LIBRARIES vrsync::agent)
unset(_vrsync_prefix)
unset(_vrsync_libdir)
unset(_vrsync_includedir)
unset(_vrsync_static_deps)
