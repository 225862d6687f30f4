// keyframes.hpp: which time steps store each node's brick (format/SPEC.md, "Keyframes"). A node
// keeps no brick at a step where the linear interpolation between its neighbouring stored states
// (what the decoders and the player draw there, format/time_step.hpp) meets the codec's error
// rule, the coding error of the stored states included.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "volreel/encoder/frame_encoder.hpp"
#include "volreel/format/decoder.hpp"

namespace volreel::encoder {

/// The error rule an interpolated brick is held to (each brick's level's ε_l and the pointwise
/// bound come with its CodedFrame):
/// - ksvd variable rate: the brick's squared error at most brick_factor·max(N·ε_l², E_coded) and
///   each 6³ block's at most block_factor·max(216·ε_l², e_coded), where E_coded and e_coded are
///   the errors of the brick as coded at that step (so an interpolated brick is never much worse
///   than the coded one, nor held to more than the tolerance; the brick factor absorbs that the
///   two stored states' coding errors are alike where the data is, so that their interpolation's
///   error fluctuates about the coded one's);
/// - fixed rate (no ε): the same with ε = 0;
/// - a pointwise bound (--max-error with ksvd, in addition; zfp's accuracy, alone): every value
///   within it.
/// - within_coded_error (for a PSNR target): the same without the tolerance (ε_l = 0). Where a
///   frame so interpolated misses the target, the encoder chooses its stretch again at
///   brick_factor 1.
struct KeyframeRule {
  double brick_factor = 1.25;
  double block_factor = 4.0;
  bool within_coded_error = false;
};

/// For the frames of one stretch of consecutive time steps (coded with their originals kept; the
/// first and the last store every node), one flag per brick of each frame: store it (1) or leave it
/// to interpolation (0). Greedy along each node's time line: from a stored state, the farthest
/// next step whose interpolation holds at every step between; a node under an empty ancestor, or
/// empty itself, is stored. Parallel (OpenMP) over nodes.
std::vector<std::vector<char>> choose_keyframes(std::span<const CodedFrame* const> frames,
                                                const format::AtomTable& atoms,
                                                const KeyframeRule& rule = {});

}  // namespace volreel::encoder
