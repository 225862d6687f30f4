# Compiler warnings and sanitizers shared by every volreel target.
add_library(volreel_warnings INTERFACE)
add_library(volreel::warnings ALIAS volreel_warnings)
target_compile_options(volreel_warnings INTERFACE
  -Wall -Wextra -Wconversion -Wsign-conversion -Wshadow -Wnon-virtual-dtor
  -Wold-style-cast -Woverloaded-virtual -Wnull-dereference -Wdouble-promotion)
# GCC 12 reports false -Wrestrict warnings inside libstdc++ for `"literal" + std::string` at -O2
# (GCC bug 105329); the check is not ours to fix.
if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU" AND CMAKE_CXX_COMPILER_VERSION VERSION_LESS 13)
  target_compile_options(volreel_warnings INTERFACE -Wno-restrict)
endif()
if(VOLREEL_WERROR)
  target_compile_options(volreel_warnings INTERFACE -Werror)
endif()

if(VOLREEL_SANITIZE)
  set(_san -fsanitize=${VOLREEL_SANITIZE} -fno-omit-frame-pointer -fno-sanitize-recover=all)
  add_compile_options(${_san})
  add_link_options(${_san})
endif()
