// frame_encoder.hpp: one frame -> a frame file (MTV-Player §3.2): every brick of the hierarchy
// (pyramid.hpp) coded by its CodingSettings — sparse coding of its 6³ blocks against the
// dictionary with quantization, or zfp — and the node table with bottom-up histograms.
#pragma once

#include <array>
#include <cstddef>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include "volreel/datasets/volume.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/dictionary/omp.hpp"
#include "volreel/encoder/coding_settings.hpp"
#include "volreel/encoder/pyramid.hpp"
#include "volreel/format/brick_decode.h"
#include "volreel/format/decoder.hpp"
#include "volreel/format/frame_file.hpp"

namespace volreel::encoder {

namespace detail {
struct QuantizeOptions;
}

/// Where a frame file's bytes go. The parts from frame_tables to zfp_streams sum to the file's
/// size; the last three are shares of the payload parts.
struct ByteBreakdown {
  std::size_t frame_tables = 0;     ///< header, level table, node table, brick offsets
  std::size_t constant_bricks = 0;  ///< 4-byte values
  std::size_t brick_headers = 0;    ///< ksvd: 20 bytes per coded brick (dequantization, layout)
  std::size_t block_entries = 0;    ///< ksvd: t + b bits per block (sparsity, mean), to a word
  std::size_t codes = 0;            ///< ksvd: a + c bits per code (atom index, value)
  std::size_t alignment = 0;        ///< ksvd: the code stream padded to a word
  std::size_t zfp_streams = 0;      ///< zfp bricks
  std::size_t coarse_levels = 0;    ///< payload bytes of the levels above the finest
  /// Payload bytes in proportion to the stored voxels that are aprons or padding (outside the
  /// level), brick by brick: an estimate of what the brick layout costs.
  double aprons_and_padding = 0;
  /// Code bytes of the finest level, each block's weighted by the share of its voxels that are
  /// the level's own (interior, inside the volume): all a frame would cost if block means, tables,
  /// coarse levels, aprons and padding were free, at the same codes.
  double finest_owned_codes = 0;
  ByteBreakdown& operator+=(const ByteBreakdown& o);
  std::size_t total() const {
    return frame_tables + constant_bricks + brick_headers + block_entries + codes + alignment +
           zfp_streams;
  }
};

struct FrameStats {
  std::size_t bricks = 0, constant_bricks = 0, empty_nodes = 0;
  std::size_t interpolated_nodes = 0;  ///< nodes without a brick at this step (keyframes.hpp)
  std::size_t blocks = 0, codes = 0;   ///< coded blocks and coefficients (ksvd)
  std::size_t bytes = 0;
  double seconds = 0;
  double seconds_pyramid = 0, seconds_bricks = 0, seconds_omp = 0,
         seconds_quantize = 0;  ///< parts of seconds
  /// Squared error summed over every value of every coded block (all levels, aprons included):
  /// of the unquantized sparse approximation, and of what the payload decodes to. Their ratio is
  /// the PSNR lost to quantization: 10·log10(quantized / unquantized).
  double unquantized_squared_error = 0, quantized_squared_error = 0;
  ByteBreakdown breakdown;
  std::array<std::size_t, 256> sparsity_histogram{};  ///< coded blocks (ksvd) by atom count
  std::array<std::size_t, VR_MEAN_BITS + 1>
      mean_bits_histogram{};                          ///< coded bricks (ksvd) by mean bits
  std::array<std::size_t, 17> coef_bits_histogram{};  ///< coded bricks (ksvd) by magnitude bits
  std::size_t split_bricks = 0;  ///< coded bricks (ksvd) with the split flag: the DCT basis alone
  std::uint64_t code_bits = 0;   ///< ksvd: bits of the code streams (padding excluded)
  /// Blocks that missed the pointwise bound (CodingSettings::max_error) even with 16-bit
  /// coefficients and Smax atoms: 0 whenever the bound holds.
  std::size_t blocks_over_bound = 0;
  /// PlaneCoding::measure_finest: the finest level's squared error summed and largest error.
  double finest_squared_error = 0, finest_max_error = 0;
};

/// One node of a frame's full octree, coded: what the keyframe choice (keyframes.hpp) and the
/// frame file need.
struct CodedBrick {
  std::uint32_t level = 0, x = 0, y = 0, z = 0;
  std::uint64_t morton = 0;
  std::vector<std::byte> payload;  ///< a 4-byte constant, a ksvd payload or a zfp stream
  std::size_t codes = 0;           ///< ksvd codes in the payload
  std::uint64_t histogram = 0;     ///< of the brick and its descendants (64 bins)
  bool constant = false;           ///< every stored voxel one value
  bool subtree_constant = false;   ///< the brick and every descendant that value (an empty node)
  float value = 0;                 ///< the constant (constant bricks)
  /// The tolerance it was coded to: ε·F^d, or r·δ where that is coarser (ksvd variable rate,
  /// CodingSettings::level_detail_ratio; 0 otherwise).
  double tolerance = 0;
  /// PlaneCoding::measure_finest, finest bricks: the squared error over the voxels that are its
  /// own (FrameStats::finest_squared_error sums them in brick order, the same for any threads).
  double squared_error = 0;
};

/// A frame coded brick by brick, before its frame file is written (FrameEncoder::code).
struct CodedFrame {
  std::size_t t = 0;
  std::vector<format::LevelGeometry> geometry;
  /// Every node of the full octree, level by level (breadth-first, Morton order inside a level):
  /// level_begin[l] is level l's first and level_begin[levels] the count.
  std::vector<CodedBrick> bricks;
  std::vector<std::size_t> level_begin;
  std::vector<std::vector<std::size_t>> children;  ///< per brick, its children's indices
  std::vector<std::size_t> parent;                 ///< per brick, its parent's (root: itself)
  /// The stored voxels (S³ each, S the brick size) of every brick of the frame, when code() was
  /// asked to keep them.
  std::vector<float> originals;
  /// The pointwise bound the bricks were coded to (--max-error or the zfp accuracy; 0 for none);
  /// each brick's tolerance is its own (CodedBrick::tolerance).
  double max_abs_error = 0;
  std::size_t window_bytes = 0;  ///< the most bytes of planes held while coding (PyramidWindow)
  format::FrameHeader header{};
  FrameStats stats;  ///< of the coding (bytes and the byte breakdown come with the frame file)
};

/// What FrameEncoder::code_planes does besides coding.
struct PlaneCoding {
  bool keep_originals = false;  ///< CodedFrame::originals
  /// FrameStats::finest_*: every finest brick's payload decoded by the CPU reference decoder
  /// against the voxels it stores, over the voxels that are its own: the frame's finest level as
  /// a reader decodes it when every node keeps its brick (no keyframe gaps), without a second pass.
  bool measure_finest = false;
  std::function<void(double)> progress;  ///< the fraction of the finest rows of bricks done
  /// A team of `members` processes codes the frame together (spatial decomposition): this one,
  /// `member`, codes the bricks whose index in CodedFrame::bricks is member modulo members and
  /// leaves the others' payloads empty. The team's writer completes the frame with the others'
  /// parts (team_part, join_team_parts).
  std::size_t members = 1, member = 0;
};

/// What a team member coded of a frame (PlaneCoding::members > 1): its bricks and its share of the
/// coding's statistics, as bytes for the team's writer.
std::vector<std::byte> team_part(const CodedFrame& coded, const PlaneCoding& options);
/// The writer's frame, coded as member 0 of PlaneCoding::members, completed from the other
/// members' parts (in member order): their bricks and statistics added, then the tree's
/// histograms and empty subtrees merged bottom-up as code_planes does for a frame coded alone.
/// Throws std::runtime_error when a part does not fit the frame.
void join_team_parts(CodedFrame& coded, std::span<const std::vector<std::byte>> parts,
                     const PlaneCoding& options);

/// Encodes frames with fixed settings and dictionary; it parallelizes inside with OpenMP, and its
/// const members may run on several threads at once (frames coded side by side).
class FrameEncoder {
 public:
  /// dictionary: required for ksvd (K ≤ 65536, M = 6). Throws InputError on bad settings.
  FrameEncoder(const dictionary::Dictionary* dictionary, CodingSettings settings);
  /// Frame t -> the frame file's bytes (every node with its brick).
  std::vector<std::byte> encode(std::size_t t, const Volume& frame,
                                FrameStats* stats = nullptr) const;
  /// Frame t coded brick by brick; keep_originals: keep the stored voxels of every brick.
  CodedFrame code(std::size_t t, const Volume& frame, bool keep_originals = false) const;
  /// The same into `coded`, reusing the storage of its originals (a stretch of frames coded one
  /// after another allocates them once).
  void code_into(std::size_t t, const Volume& frame, CodedFrame& coded,
                 bool keep_originals = false) const;
  /// The same for a frame of size `dims` read a few planes at a time (`read`: the finest planes
  /// [z_begin, z_end), as SeriesReader::read_slab delivers them): each level holds about one row
  /// of bricks' planes (PyramidWindow), so a frame larger than memory is coded in pieces. The
  /// bricks come out as code_into's.
  void code_planes(std::size_t t, const Dims& dims, const PyramidWindow::ReadPlanes& read,
                   CodedFrame& coded, const PlaneCoding& options = {}) const;
  /// The frame file of a coded frame, with the bricks of the nodes keep[i] (one flag per brick of
  /// coded.bricks; empty: every node) and no brick for the other nodes of its tree (they are
  /// interpolated: format/SPEC.md, "Keyframes"). An empty node always keeps its brick. stats: the
  /// coding's statistics with the bytes written.
  std::vector<std::byte> write(const CodedFrame& coded, std::span<const char> keep = {},
                               FrameStats* stats = nullptr) const;
  /// One stored brick (S³ values of shape(), x fastest) -> its payload: a 4-byte constant, a ksvd
  /// payload or a zfp stream (the same coding encode() applies to every brick).
  std::vector<std::byte> encode_brick(std::span<const float> brick) const;
  const CodingSettings& settings() const { return settings_; }
  /// ksvd: the dictionary's atoms as the decoders read the payloads it writes
  /// (format::atom_table, the DCT basis found once); empty for zfp.
  const format::AtomTable& atoms() const { return atoms_; }
  /// The brick tiling of the frames it codes (CodingSettings::brick_size).
  format::BrickShape shape() const { return {settings_.brick_size}; }
  /// The Lagrangian rule's minimum atom gain, lagrangian_factor·m·ε² (data units²); 0 for the
  /// other rules and codecs.
  double atom_gain_threshold() const;

 private:
  const dictionary::Dictionary* dictionary_;
  CodingSettings settings_;
  std::shared_ptr<const dictionary::BatchOmp> omp_;
  /// CodingSettings::split_bricks, when the dictionary has learned atoms before the DCT basis:
  /// the basis alone (the dictionary's last 215 atoms) and its pursuit; else empty and null.
  Eigen::MatrixXf dct_atoms_;
  std::shared_ptr<const dictionary::BatchOmp> dct_omp_;
  /// The atoms before the DCT basis when the dictionary ends with it (the payloads' band split,
  /// format/SPEC.md), else 0; at most 4095.
  std::uint32_t band_split_ = 0;
  format::AtomTable atoms_{};
  detail::QuantizeOptions quantize_options() const;
  /// The price of a code when a brick's two codings are compared (split_bricks):
  /// lagrangian_factor·m·ε², the Lagrangian rule's least gain of an atom, under either variable
  /// rate rule.
  double split_code_cost() const;
};

}  // namespace volreel::encoder
