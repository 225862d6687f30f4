# Compiler warnings and sanitizers shared by every volreel target.
add_library(volreel_warnings INTERFACE)
add_library(volreel::warnings ALIAS volreel_warnings)
target_compile_options(volreel_warnings INTERFACE
  -Wall -Wextra -Wconversion -Wsign-conversion -Wshadow -Wnon-virtual-dtor
  -Wold-style-cast -Woverloaded-virtual -Wnull-dereference -Wdouble-promotion)
if(VOLREEL_WERROR)
  target_compile_options(volreel_warnings INTERFACE -Werror)
endif()

if(VOLREEL_SANITIZE)
  set(_san -fsanitize=${VOLREEL_SANITIZE} -fno-omit-frame-pointer -fno-sanitize-recover=all)
  add_compile_options(${_san})
  add_link_options(${_san})
endif()
