// encoder.hpp: the whole encoder (MTV-Player §3.2) in one include — frames to frame files and a
// series to a container, one header per job:
//   coding_settings.hpp     how bricks are coded (codec, rate rule, quantization)
//   pyramid.hpp             the brick hierarchy of a frame (levels, bricks with aprons)
//   frame_encoder.hpp       one frame -> a frame file, with its byte breakdown
//   series_encoder.hpp      a series -> a container, with resume
//   tolerance.hpp           choosing ε: given, from a PSNR, a size target, or the dictionary
//   default_dictionary.hpp  the dictionary an encode trains when it is given none
//   encode.hpp              all of it: value range, dictionary, ε, the series encoded
#pragma once

#include "volreel/encoder/coding_settings.hpp"
#include "volreel/encoder/default_dictionary.hpp"
#include "volreel/encoder/encode.hpp"
#include "volreel/encoder/frame_encoder.hpp"
#include "volreel/encoder/pyramid.hpp"
#include "volreel/encoder/series_encoder.hpp"
#include "volreel/encoder/tolerance.hpp"
