# FindFFTW3: single-precision FFTW3 with its OpenMP threading library.
# Debian's libfftw3-dev ships pkg-config files but no CMake package, so this module looks for
# the libraries directly. Defines the imported target FFTW3::fftw3f_omp (which links fftw3f).
find_path(FFTW3_INCLUDE_DIR fftw3.h)
find_library(FFTW3F_LIBRARY fftw3f)
find_library(FFTW3F_OMP_LIBRARY fftw3f_omp)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(FFTW3 REQUIRED_VARS FFTW3_INCLUDE_DIR FFTW3F_LIBRARY FFTW3F_OMP_LIBRARY)
if(FFTW3_FOUND AND NOT TARGET FFTW3::fftw3f_omp)
  add_library(FFTW3::fftw3f UNKNOWN IMPORTED)
  set_target_properties(FFTW3::fftw3f PROPERTIES IMPORTED_LOCATION ${FFTW3F_LIBRARY}
    INTERFACE_INCLUDE_DIRECTORIES ${FFTW3_INCLUDE_DIR})
  add_library(FFTW3::fftw3f_omp UNKNOWN IMPORTED)
  set_target_properties(FFTW3::fftw3f_omp PROPERTIES IMPORTED_LOCATION ${FFTW3F_OMP_LIBRARY}
    INTERFACE_LINK_LIBRARIES FFTW3::fftw3f)
endif()
mark_as_advanced(FFTW3_INCLUDE_DIR FFTW3F_LIBRARY FFTW3F_OMP_LIBRARY)
