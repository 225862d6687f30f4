// frame_encoder.cpp: one frame -> its frame file, in four steps (FrameEncoder::encode): the cells
// of the full octree, every brick coded in chunks, histograms and constant subtrees bottom-up,
// and the node table of the nodes kept.
#include "volreel/encoder/frame_encoder.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <exception>
#include <functional>
#include <stdexcept>
#include <string>

#include "detail.hpp"
#include "volreel/encoder/pyramid.hpp"
#include "volreel/format/brick_decode.h"
#include "volreel/format/bytes.hpp"
#include "volreel/format/decoder.hpp"
#include "volreel/format/dictionary_file.hpp"

namespace volreel::encoder {

void detail::require_brick_blocks(std::uint32_t block_size, const std::string& where) {
  if (block_size != VR_BLOCK_SIZE)
    throw InputError(where + "the dictionary has blocks of " + std::to_string(block_size) +
                     "^3; volreel's bricks need 6^3 (volreel train --block 6, its default)");
}

std::uint64_t detail::frame_bricks(const Dims& dims, format::BrickShape shape) {
  std::uint64_t bricks = 0;
  for (const format::LevelGeometry& level : format::level_geometry(
           {static_cast<std::uint32_t>(dims.x), static_cast<std::uint32_t>(dims.y),
            static_cast<std::uint32_t>(dims.z)},
           shape))
    bricks += std::uint64_t{level.grid[0]} * level.grid[1] * level.grid[2];
  return bricks;
}

double detail::stretch_bytes_per_frame(const Dims& dims, format::BrickShape shape) {
  return 4.0 *
         (static_cast<double>(dims.voxels()) +
          static_cast<double>(frame_bricks(dims, shape)) * static_cast<double>(shape.voxels()));
}

std::size_t detail::side_by_side_batch(const Dims& dims, format::BrickShape shape,
                                       std::uint32_t gap, std::uint64_t memory) {
  if (!frames_side_by_side(dims, shape)) return 0;
  const double fit =
      std::floor(static_cast<double>(memory) / (2 * stretch_bytes_per_frame(dims, shape))) -
      (static_cast<double>(gap) + 1);
  const double batch = std::min(fit, 4.0 * static_cast<double>(side_by_side_frames()));
  return batch >= 2 ? static_cast<std::size_t>(batch) : 0;
}

bool detail::frames_side_by_side(const Dims& dims, format::BrickShape shape) {
  const auto threads = static_cast<std::uint64_t>(omp_get_max_threads());
  return threads > 1 && frame_bricks(dims, shape) < side_by_side_bricks_per_thread * threads;
}

std::size_t detail::side_by_side_frames() {
  return static_cast<std::size_t>(std::max(1, omp_get_max_threads()));
}

void detail::for_each_side_by_side(std::size_t n, const std::function<void(std::size_t)>& fn) {
  if (n == 1) return fn(0);
  // One level of threads: a call's own parallel regions run on its thread.
  const int levels = omp_get_max_active_levels();
  omp_set_max_active_levels(1);
  std::exception_ptr failure;
#pragma omp parallel for schedule(dynamic, 1)
  for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(n); ++i) {
    try {
      fn(static_cast<std::size_t>(i));
    } catch (...) {
#pragma omp critical(volreel_side_by_side_failure)
      if (!failure) failure = std::current_exception();
    }
  }
  omp_set_max_active_levels(levels);
  if (failure) std::rethrow_exception(failure);
}

using detail::Clock;
using detail::QuantizeOptions;
using detail::seconds_since;

namespace {

/// The most atoms a block may have: one per value of the block (the format's 8-bit sparsity
/// field holds up to 255).
constexpr int max_sparsity = static_cast<int>(VR_BLOCK_LENGTH);
/// Coefficient bits of fixed rate, which has no ε to set a step from (--coef-bits overrides).
constexpr std::uint32_t fixed_rate_coef_bits = 8;

/// Bricks coded per batch-OMP call: about 32 bricks of 36³ (memory: 1.5 M floats ×2).
std::size_t chunk_bricks(format::BrickShape shape) {
  return std::max<std::size_t>(1, 32 * format::BrickShape{}.voxels() / shape.voxels());
}

using Cell = CodedBrick;

/// The full octree's cells, level by level: level_begin[l] is the first cell of level l and
/// level_begin[levels] the cell count.
struct OctreeCells {
  std::vector<Cell> cells;
  std::vector<std::size_t> level_begin;
};

/// What coding the bricks of a frame needs: the settings, and for ksvd the pursuit, the atoms, the
/// quantization and the Lagrangian rule's block weights.
struct BrickCoding {
  const CodingSettings& settings;
  format::BrickShape shape;
  const dictionary::BatchOmp* omp = nullptr;  ///< ksvd
  const Eigen::MatrixXf* atoms = nullptr;     ///< ksvd
  /// ksvd, CodingSettings::split_bricks with learned atoms before the DCT basis: its pursuit and
  /// atoms alone (else null).
  const dictionary::BatchOmp* dct_omp = nullptr;
  const Eigen::MatrixXf* dct_atoms = nullptr;
  QuantizeOptions quantize;
  double atom_gain_threshold = 0;
  std::size_t levels = 0;
  /// Lagrangian rule: each block's atom gains are weighed by the share of its voxels the decoder
  /// reads and by its brick's 1/s² (coded to s·ε: brick_scale).
  bool weighted = false;
  bool measure_finest = false;       ///< PlaneCoding::measure_finest
  format::AtomTable decode_atoms{};  ///< ksvd, measure_finest: the atoms payloads decode with
  double split_code_cost = 0;        ///< ksvd: FrameEncoder::split_code_cost

  bool ksvd() const { return settings.codec == format::Codec::ksvd; }
  /// The factor on ε for a brick of `level` whose own voxels differ from the frame by
  /// `detail` (mean square, PyramidWindow::brick_detail): F^d, or r·δ/ε where that is larger
  /// (CodingSettings::level_detail_ratio); 1 unless the Lagrangian rule.
  double brick_scale(std::uint32_t level, double detail) const {
    if (!(atom_gain_threshold > 0)) return 1.0;
    const double scale =
        std::pow(settings.level_tolerance_factor, static_cast<double>(levels - 1 - level));
    const double from_detail =
        settings.tolerance > 0
            ? settings.level_detail_ratio * std::sqrt(std::max(detail, 0.0)) / settings.tolerance
            : 0.0;
    return std::max(scale, from_detail);
  }
  /// A coded brick's factor on ε, from the tolerance extract_chunk gave it.
  double scale_of(const CodedBrick& c) const {
    return atom_gain_threshold > 0 && settings.tolerance > 0 ? c.tolerance / settings.tolerance
                                                             : 1.0;
  }
};

/// Batch-OMP's inputs and outputs for one chunk, reused from chunk to chunk.
struct ChunkWorkspace {
  explicit ChunkWorkspace(format::BrickShape shape)
      : bricks(chunk_bricks(shape) * shape.voxels()) {}
  std::vector<float> bricks;
  Eigen::MatrixXf columns;
  std::vector<float> means, weights;
  dictionary::SparseCodes codes, dct_codes;
};

/// Bytes of a packed ksvd payload's code stream (after its header and entries).
std::size_t code_stream_bytes(std::span<const std::byte> payload) {
  vr_uint header[VR_HEADER_WORDS];
  std::memcpy(header, payload.data(), sizeof header);
  return payload.size() - 4 * std::size_t{vr_code_first_word(vr_layout_word(header),
                                                             vr_box_entries(vr_box_word(header)))};
}

/// Quantizes the brick of blocks first_block .. first_block + n³ − 1 of `codes` (quantize_brick)
/// and, when dct_codes is not null, the same blocks' codes of the DCT basis alone (dct_atoms, coded
/// by dct_omp; the payload's split flag), keeping the better (the first on a tie): the one with
/// fewer blocks over the max-error bound, then the one of the lower cost, its squared error
/// (weighed as the Lagrangian rule weighs the blocks, QuantizeOptions::block_weights) plus
/// code_cost (the price of a code, lagrangian_factor·m·ε²) per code's worth of its bytes, a
/// code's worth being the first coding's code stream bytes per code. codes null (with dct_codes):
/// the basis's codes alone, as if they were kept. Adds what it kept to *result; *used_dct says
/// which.
std::vector<std::byte> quantize_either(format::BrickShape shape, const float* columns,
                                       const float* means, const dictionary::SparseCodes* codes,
                                       const dictionary::SparseCodes* dct_codes,
                                       std::size_t first_block, const Eigen::MatrixXf& atoms,
                                       const dictionary::BatchOmp* dct_omp,
                                       const Eigen::MatrixXf* dct_atoms,
                                       const QuantizeOptions& options, double code_cost,
                                       detail::BrickQuantization* result, bool* used_dct) {
  *used_dct = false;
  if (!dct_codes)
    return detail::quantize_brick(shape, columns, means, *codes, first_block, atoms, options,
                                  result);
  detail::BrickQuantization all, basis;
  QuantizeOptions split = options;
  split.from_split = true;
  split.orthonormal_atoms = dct_omp->orthonormal();
  std::vector<std::byte> alone = detail::quantize_brick(shape, columns, means, *dct_codes,
                                                        first_block, *dct_atoms, split, &basis);
  std::vector<std::byte> payload;
  if (codes)
    payload =
        detail::quantize_brick(shape, columns, means, *codes, first_block, atoms, options, &all);
  bool dct;
  if (!codes) {
    dct = true;
  } else if (basis.blocks_over_bound != all.blocks_over_bound) {
    dct = basis.blocks_over_bound < all.blocks_over_bound;
  } else if (all.codes > 0 && payload.size() > 4) {
    const double per_byte =
        code_cost * static_cast<double>(all.codes) /
        static_cast<double>(std::max<std::size_t>(code_stream_bytes(payload), 1));
    dct = basis.weighted_error + per_byte * static_cast<double>(alone.size()) <
          all.weighted_error + per_byte * static_cast<double>(payload.size());
  } else {
    dct = alone.size() < payload.size();
  }
  const detail::BrickQuantization& kept = dct ? basis : all;
  result->squared_error += kept.squared_error;
  result->weighted_error += kept.weighted_error;
  result->codes += kept.codes;
  result->blocks_over_bound += kept.blocks_over_bound;
  *used_dct = dct;
  return dct ? alone : payload;
}

/// Adds a stored brick's payload to the byte breakdown and sparsity histogram of a frame.
void add_to_breakdown(format::BrickShape shape, const Cell& c,
                      const std::array<std::uint32_t, 3>& level_dims, bool coarse, bool ksvd,
                      FrameStats& st) {
  ByteBreakdown& b = st.breakdown;
  const std::size_t size = c.payload.size();
  const std::uint32_t blocks = shape.blocks();
  // Of each block, the voxels that are the level's own.
  std::array<float, VR_MAX_BLOCKS_PER_AXIS * VR_MAX_BLOCKS_PER_AXIS * VR_MAX_BLOCKS_PER_AXIS>
      shares{};
  detail::owned_block_shares(shape, c.x, c.y, c.z, level_dims, shares.data());
  double stored_blocks = blocks;  // a ksvd payload: its box of coded blocks only
  if (c.constant) {
    b.constant_bricks += size;
  } else if (!ksvd) {
    b.zfp_streams += size;
  } else {
    // One zero word more: a Rice code's look-ahead (brick_decode.h).
    std::vector<vr_uint> words(std::max<std::size_t>(size / 4, VR_HEADER_WORDS) + 1, 0u);
    std::memcpy(words.data(), c.payload.data(), size / 4 * 4);
    const vr_uint layout = vr_layout_word(words.data()), box = vr_box_word(words.data());
    stored_blocks = vr_box_entries(box);
    b.brick_headers += 4 * VR_HEADER_WORDS;
    b.block_entries += 4 * vr_entry_words(layout, vr_box_entries(box));
    const vr_uint first = vr_code_first_word(layout, vr_box_entries(box));
    ++st.mean_bits_histogram[vr_layout_mean_bits(layout)];
    ++st.coef_bits_histogram[vr_layout_coef_bits(layout)];
    st.split_bricks += vr_box_from_split(box);
    const vr_uint band_word = vr_band_word(words.data());
    vr_uint bit = 0;
    for (std::uint32_t k = 0, e = 0; k < blocks; ++k) {
      const vr_uint sparsity =
          vr_block_in_box(box, shape.blocks_per_axis(), k)
              ? vr_entry_sparsity(layout, vr_block_entry(words.data(), layout, e++))
              : 0u;
      const vr_uint start = bit;
      vr_uint next_atom = vr_block_first_atom(layout, box), run = 0, atom = 0;
      const vr_uint block_band_word = vr_block_band_word(band_word, box, sparsity);
      for (vr_uint j = 0; j < sparsity; ++j)
        vr_read_code(words.data(), first, layout, block_band_word, box, sparsity, bit, next_atom,
                     run, atom);
      ++st.sparsity_histogram[sparsity];
      if (!coarse) b.finest_owned_codes += (bit - start) / 8.0 * static_cast<double>(shares[k]);
    }
    st.code_bits += bit;
    b.codes += bit / 8;
    b.alignment += size - 4 * first - bit / 8;
  }
  if (coarse) b.coarse_levels += size;
  // The blocks' owned shares average to the brick's interior voxels inside the level: the rest of
  // the stored voxels are apron or padding. A ksvd payload stores its box of coded blocks only.
  double owned = 0;
  for (std::uint32_t k = 0; k < blocks; ++k) owned += static_cast<double>(shares[k]);
  b.aprons_and_padding += static_cast<double>(size) * (1 - owned / stored_blocks);
}

/// Step 1: every cell of every level, breadth-first, Morton order inside a level.
OctreeCells octree_cells(const std::vector<format::LevelGeometry>& geometry) {
  const std::size_t levels = geometry.size();
  OctreeCells octree;
  std::vector<Cell>& cells = octree.cells;
  octree.level_begin.assign(levels + 1, 0);
  for (std::size_t l = 0; l < levels; ++l) {
    octree.level_begin[l] = cells.size();
    const auto& g = geometry[l].grid;
    for (std::uint32_t z = 0; z < g[2]; ++z)
      for (std::uint32_t y = 0; y < g[1]; ++y)
        for (std::uint32_t x = 0; x < g[0]; ++x) {
          Cell c;
          c.level = static_cast<std::uint32_t>(l);
          c.x = x, c.y = y, c.z = z;
          c.morton = format::morton3(x, y, z);
          cells.push_back(std::move(c));
        }
    std::sort(cells.begin() + static_cast<std::ptrdiff_t>(octree.level_begin[l]), cells.end(),
              [](const Cell& a, const Cell& b) { return a.morton < b.morton; });
  }
  octree.level_begin[levels] = cells.size();
  return octree;
}

/// Step 2a: the stored voxels of each cell of a chunk into `bricks`, its histogram over
/// [lo, hi], the constant test; constant bricks and (zfp) every brick get their payload here.
void extract_chunk(const PyramidWindow& window, std::span<Cell> chunk, float* bricks, float lo,
                   float hi, const BrickCoding& coding) {
  const bool ksvd = coding.ksvd();
  const std::size_t brick_voxels = coding.shape.voxels();
#pragma omp parallel for schedule(dynamic, 1)
  for (std::ptrdiff_t j = 0; j < static_cast<std::ptrdiff_t>(chunk.size()); ++j) {
    Cell& c = chunk[static_cast<std::size_t>(j)];
    float* brick = bricks + static_cast<std::size_t>(j) * brick_voxels;
    window.extract_brick(c.level, c.x, c.y, c.z, {brick, brick_voxels});
    float mn = brick[0], mx = brick[0];
    std::uint64_t hist = 0;
    for (std::size_t v = 0; v < brick_voxels; ++v) {
      mn = std::min(mn, brick[v]);
      mx = std::max(mx, brick[v]);
      hist |= std::uint64_t{1} << format::histogram_bin(brick[v], lo, hi);
    }
    c.histogram = hist;
    c.tolerance = 0;
    if (ksvd && coding.settings.fixed_sparsity == 0) {
      const bool coarse = c.level + 1 < coding.levels;
      c.tolerance = coding.settings.tolerance *
                    coding.brick_scale(c.level, coarse && coding.settings.uses_level_detail()
                                                    ? window.brick_detail(c.level, c.x, c.y, c.z)
                                                    : 0.0);
    }
    c.constant = mn == mx;
    c.value = mn;
    if (c.constant)
      c.payload = detail::constant_payload(mn);
    else if (!ksvd)
      c.payload = detail::zfp_payload(coding.shape, brick, coding.settings.zfp_accuracy);
  }
}

/// Step 2b (ksvd): the blocks of the chunk's non-constant bricks (`coded`, indices into the chunk)
/// and their weights, batch-OMP on all of them at once, then each brick quantized into its
/// payload. `part` is when the chunk's extraction began (its time counts as brick extraction).
void code_ksvd_chunk(const std::vector<format::LevelGeometry>& geometry, std::span<Cell> chunk,
                     const std::vector<std::size_t>& coded, const BrickCoding& coding,
                     ChunkWorkspace& work, Clock::time_point part, FrameStats& st) {
  const std::size_t brick_blocks = coding.shape.blocks(), brick_voxels = coding.shape.voxels();
  const auto blocks = static_cast<Eigen::Index>(coded.size() * brick_blocks);
  work.columns.resize(VR_BLOCK_LENGTH, blocks);
  work.means.resize(static_cast<std::size_t>(blocks));
  work.weights.resize(coding.weighted ? static_cast<std::size_t>(blocks) : 0);
  // Each brick's box word of coded blocks (format::coded_box): the blocks past it are not coded.
  const vr_uint per_axis = coding.shape.blocks_per_axis();
  std::vector<vr_uint> boxes(coded.size());
  for (std::size_t k = 0; k < coded.size(); ++k) {
    const Cell& c = chunk[coded[k]];
    const auto box = format::coded_box(coding.shape, {c.x, c.y, c.z}, geometry[c.level].dims);
    boxes[k] = vr_make_box(box[0], box[1], box[2]);
  }
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t k = 0; k < static_cast<std::ptrdiff_t>(coded.size()); ++k) {
    const auto kk = static_cast<std::size_t>(k);
    detail::brick_to_blocks(coding.shape, work.bricks.data() + coded[kk] * brick_voxels,
                            work.columns.data() + kk * brick_blocks * VR_BLOCK_LENGTH,
                            work.means.data() + kk * brick_blocks);
    if (coding.weighted) {
      const Cell& c = chunk[coded[kk]];
      float* w = work.weights.data() + kk * brick_blocks;
      if (coding.settings.weight_owned_voxels)
        detail::owned_block_weights(coding.shape, c.x, c.y, c.z, geometry[c.level].dims, w);
      else
        std::fill(w, w + brick_blocks, 1.0f);
      const double scale = coding.scale_of(c);
      for (std::size_t b = 0; b < brick_blocks; ++b)  // blocks outside the box: not coded
        w[b] = vr_block_in_box(boxes[kk], per_axis, static_cast<vr_uint>(b))
                   ? static_cast<float>(static_cast<double>(w[b]) / (scale * scale))
                   : 0.0f;
    }
  }
  st.seconds_bricks += seconds_since(part);
  part = Clock::now();
  const bool learned = !coding.dct_omp || coding.settings.learned_pursuit;
  if (learned) coding.omp->encode(work.columns, work.codes, work.weights);
  if (coding.dct_omp) coding.dct_omp->encode(work.columns, work.dct_codes, work.weights);
  st.seconds_omp += seconds_since(part);
  part = Clock::now();
  double quantized_error = 0;
  std::size_t code_count = 0, over_bound = 0;
  const QuantizeOptions& qo = coding.quantize;
  std::vector<char> used_dct(coded.size(), 0);  // the brick kept the basis's codes
  // Fewer bricks than threads (a small volume's one brick a frame): the bricks one after the
  // other, each brick's blocks on all threads.
  const bool by_blocks = coded.size() < static_cast<std::size_t>(omp_get_max_threads());
#pragma omp parallel for schedule(dynamic, 1) reduction(+ : quantized_error, code_count, over_bound) if (!by_blocks)
  for (std::ptrdiff_t k = 0; k < static_cast<std::ptrdiff_t>(coded.size()); ++k) {
    const auto kk = static_cast<std::size_t>(k);
    Cell& cell = chunk[coded[kk]];
    QuantizeOptions brick_qo = qo;  // the means' and coefficients' steps follow the level's ε
    brick_qo.mean_step *= coding.scale_of(cell);
    brick_qo.coef_step *= coding.scale_of(cell);
    brick_qo.box = boxes[kk];
    brick_qo.parallel_blocks = by_blocks;
    if (coding.weighted) brick_qo.block_weights = work.weights.data() + kk * brick_blocks;
    detail::BrickQuantization result;
    bool dct = false;
    cell.payload = quantize_either(
        coding.shape, work.columns.data() + kk * brick_blocks * VR_BLOCK_LENGTH,
        work.means.data() + kk * brick_blocks, learned ? &work.codes : nullptr,
        coding.dct_omp ? &work.dct_codes : nullptr, kk * brick_blocks, *coding.atoms,
        coding.dct_omp, coding.dct_atoms, brick_qo, coding.split_code_cost, &result, &dct);
    used_dct[kk] = dct;
    cell.codes = result.codes;
    code_count += result.codes;
    quantized_error += result.squared_error;
    over_bound += result.blocks_over_bound;
  }
  st.codes += code_count;
  st.blocks_over_bound += over_bound;
  st.quantized_squared_error += quantized_error;
  st.seconds_quantize += seconds_since(part);
  for (std::size_t k = 0; k < coded.size(); ++k) {  // the coded blocks, as quantize_brick's
    const dictionary::SparseCodes& kept = used_dct[k] ? work.dct_codes : work.codes;
    for (std::size_t b = 0; b < brick_blocks; ++b)
      if (vr_block_in_box(boxes[k], per_axis, static_cast<vr_uint>(b)))
        st.unquantized_squared_error +=
            static_cast<double>(kept.residual_energy[k * brick_blocks + b]);
  }
  st.blocks += static_cast<std::size_t>(blocks);
}

/// Step 2 for one chunk: extract, histogram, constant test; then code the non-constant bricks.
/// `originals`: where the chunk's stored voxels go, brick by brick (null: nowhere).
void code_chunk(const PyramidWindow& window, std::span<Cell> chunk, float lo, float hi,
                const BrickCoding& coding, ChunkWorkspace& work, FrameStats& st,
                const std::function<float*(std::size_t j)>& originals) {
  const auto part = Clock::now();
  extract_chunk(window, chunk, work.bricks.data(), lo, hi, coding);
  const std::size_t brick_voxels = coding.shape.voxels();
  if (originals)
    for (std::size_t j = 0; j < chunk.size(); ++j)
      std::copy_n(work.bricks.data() + j * brick_voxels, brick_voxels, originals(j));
  if (!coding.ksvd()) {
    st.seconds_bricks += seconds_since(part);
    return;
  }
  std::vector<std::size_t> coded;
  for (std::size_t j = 0; j < chunk.size(); ++j)
    if (!chunk[j].constant) coded.push_back(j);
  if (!coded.empty()) code_ksvd_chunk(window.geometry(), chunk, coded, coding, work, part, st);
}

/// PlaneCoding::measure_finest for a chunk of finest bricks whose stored voxels are in `bricks`:
/// each payload decoded, compared over the brick's interior inside the level.
void measure_chunk(std::span<Cell> chunk, const float* bricks,
                   const std::array<std::uint32_t, 3>& dims, const BrickCoding& coding,
                   FrameStats& st) {
  double worst = 0;
  const format::BrickShape shape = coding.shape;
  const std::uint32_t brick_interior = shape.interior(), brick_size = shape.size;
#pragma omp parallel for schedule(dynamic, 1) reduction(max : worst)
  for (std::ptrdiff_t j = 0; j < static_cast<std::ptrdiff_t>(chunk.size()); ++j) {
    Cell& c = chunk[static_cast<std::size_t>(j)];
    double squared = 0;
    std::vector<float> decoded(shape.voxels());
    format::decode_payload(c.payload, coding.settings.codec, coding.settings.zfp_accuracy,
                           coding.decode_atoms, shape, decoded, "<frame being coded>", 0);
    const float* original = bricks + static_cast<std::size_t>(j) * shape.voxels();
    // Brick voxel a ∈ [1, I + 1) is level voxel I·x + a − 1 on each axis (I the interior).
    const std::uint32_t cell[3] = {c.x, c.y, c.z};
    std::uint32_t end[3];
    for (int a = 0; a < 3; ++a)
      end[a] = std::min<std::uint32_t>(
          brick_interior, dims[static_cast<std::size_t>(a)] - brick_interior * cell[a]);
    for (std::uint32_t k = 0; k < end[2]; ++k)
      for (std::uint32_t jj = 0; jj < end[1]; ++jj)
        for (std::uint32_t i = 0; i < end[0]; ++i) {
          const std::size_t v = ((std::size_t{k} + 1) * brick_size + jj + 1) * brick_size + i + 1;
          const double e = static_cast<double>(decoded[v]) - static_cast<double>(original[v]);
          squared += e * e;
          worst = std::max(worst, std::abs(e));
        }
    c.squared_error = squared;
  }
  st.finest_max_error = std::max(st.finest_max_error, worst);
}

/// FrameStats::finest_squared_error: the bricks' own, summed in brick order.
double finest_squared_error(std::span<const Cell> cells) {
  double sum = 0;
  for (const Cell& c : cells) sum += c.squared_error;
  return sum;
}

/// Step 2: the bricks row by row (bricks of one level and one z), each row as soon as the window
/// holds its planes, in chunks; planes no row needs any more leave the window.
void code_bricks(PyramidWindow& window, std::vector<Cell>& cells,
                 const std::vector<std::size_t>& level_begin, float lo, float hi,
                 const BrickCoding& coding, FrameStats& st, std::vector<float>* originals,
                 const PlaneCoding& options) {
  const std::function<void(double)>& progress = options.progress;
  const std::vector<format::LevelGeometry>& geometry = window.geometry();
  const std::size_t levels = geometry.size(), finest = levels - 1;
  const std::size_t brick_voxels = coding.shape.voxels(), brick_interior = coding.shape.interior();
  const std::size_t chunk_size = chunk_bricks(coding.shape);
  // A buffer of the right size is reused as it is (every value is overwritten below).
  if (originals && originals->size() != cells.size() * brick_voxels)
    originals->resize(cells.size() * brick_voxels);
  std::vector<std::vector<std::vector<std::size_t>>> rows(levels);  // rows[l][z]: cells, Morton
  for (std::size_t l = 0; l < levels; ++l) {
    rows[l].resize(geometry[l].grid[2]);
    for (std::size_t i = level_begin[l]; i < level_begin[l + 1]; ++i)
      if (i % options.members == options.member) rows[l][cells[i].z].push_back(i);
  }
  // The planes row z of a level needs: its bricks' S planes, Iz − 1 .. Iz + I, clamped.
  const auto row_end = [&](std::size_t l, std::size_t z) {
    return std::min<std::size_t>(brick_interior * (z + 1) + 1, window.planes(l));
  };
  ChunkWorkspace work(coding.shape);
  std::vector<Cell> chunk;
  std::vector<std::size_t> next(levels, 0);  // per level, the next row to code
  for (;;) {
    const auto part = Clock::now();
    window.advance(next[finest] < rows[finest].size() ? row_end(finest, next[finest])
                                                      : window.planes(finest));
    st.seconds_pyramid += seconds_since(part);
    bool more = false;
    for (std::size_t l = 0; l < levels; ++l) {
      for (; next[l] < rows[l].size() && window.end(l) >= row_end(l, next[l]); ++next[l]) {
        const std::vector<std::size_t>& row = rows[l][next[l]];
        for (std::size_t begin = 0; begin < row.size(); begin += chunk_size) {
          const std::size_t n = std::min(chunk_size, row.size() - begin);
          chunk.clear();
          for (std::size_t j = 0; j < n; ++j) chunk.push_back(std::move(cells[row[begin + j]]));
          std::function<float*(std::size_t)> place;
          if (originals)
            place = [&](std::size_t j) {
              return originals->data() + row[begin + j] * brick_voxels;
            };
          code_chunk(window, chunk, lo, hi, coding, work, st, place);
          if (coding.measure_finest && l == finest)
            measure_chunk(chunk, work.bricks.data(), geometry[l].dims, coding, st);
          for (std::size_t j = 0; j < n; ++j) cells[row[begin + j]] = std::move(chunk[j]);
        }
      }
      more = more || next[l] < rows[l].size();
      // Row z's bricks start at plane Iz − 1.
      window.release(l, next[l] < rows[l].size()
                            ? std::max<std::size_t>(brick_interior * next[l], 1) - 1
                            : window.planes(l));
    }
    if (progress)
      progress(static_cast<double>(next[finest]) / static_cast<double>(rows[finest].size()));
    if (!more) break;
  }
}

/// Step 3: bottom-up, histograms OR'ed into parents; a subtree is constant when the node and all
/// its children are constant subtrees of one value. Children of cell (x,y,z) are found by Morton
/// code: 8·morton + d within the next level. Returns the children of every cell.
std::vector<std::vector<std::size_t>> merge_subtrees(OctreeCells& octree) {
  std::vector<Cell>& cells = octree.cells;
  const std::vector<std::size_t>& level_begin = octree.level_begin;
  const std::size_t levels = level_begin.size() - 1;
  std::vector<std::vector<std::size_t>> children(cells.size());
  for (std::size_t l = 0; l + 1 < levels; ++l) {
    std::size_t p = level_begin[l];
    for (std::size_t i = level_begin[l + 1]; i < level_begin[l + 2]; ++i) {
      while (cells[p].morton != cells[i].morton >> 3) ++p;  // both sorted by Morton code
      children[p].push_back(i);
    }
  }
  for (std::size_t i = cells.size(); i-- > 0;) {
    Cell& c = cells[i];
    c.subtree_constant = c.constant;
    for (std::size_t k : children[i]) {
      c.histogram |= cells[k].histogram;
      if (!cells[k].subtree_constant || cells[k].value != c.value) c.subtree_constant = false;
    }
  }
  return children;
}

/// Step 3 for a coded frame: merge_subtrees over its bricks, and each brick's parent.
void link_tree(CodedFrame& coded) {
  OctreeCells octree{std::move(coded.bricks), std::move(coded.level_begin)};
  coded.children = merge_subtrees(octree);
  coded.bricks = std::move(octree.cells);
  coded.level_begin = std::move(octree.level_begin);
  coded.parent.assign(coded.bricks.size(), 0);
  for (std::size_t i = 0; i < coded.children.size(); ++i)
    for (std::size_t c : coded.children[i]) coded.parent[c] = i;
}

/// Step 4: keep the nodes not under an empty node; number them breadth-first; link first
/// children. Moves the kept cells' payloads into `out` and counts their bytes in `st`.
void build_node_table(const CodedFrame& coded, std::span<const char> keep_brick, bool ksvd,
                      format::BrickShape shape, format::FrameContents& out, FrameStats& st) {
  const std::vector<Cell>& cells = coded.bricks;
  const std::vector<std::size_t>& level_begin = coded.level_begin;
  const std::vector<std::vector<std::size_t>>& children = coded.children;
  const std::size_t levels = level_begin.size() - 1;
  std::vector<char> kept(cells.size(), 0);
  if (kept.empty()) throw std::logic_error("a frame has at least one brick");
  kept.front() = 1;
  std::vector<std::uint32_t> index(cells.size(), 0);
  for (std::size_t l = 0; l < levels; ++l) {
    format::LevelEntry e{};
    e.first_node = static_cast<std::uint32_t>(out.nodes.size());
    for (std::size_t i = level_begin[l]; i < level_begin[l + 1]; ++i) {
      if (!kept[i]) continue;
      index[i] = static_cast<std::uint32_t>(out.nodes.size());
      format::Node node{};
      node.histogram = cells[i].histogram;
      node.brick = format::no_brick;
      if (keep_brick.empty() || keep_brick[i] || cells[i].subtree_constant) {
        node.brick = static_cast<std::uint32_t>(out.payloads.size());
        add_to_breakdown(shape, cells[i], coded.geometry[l].dims, l + 1 < levels, ksvd, st);
        out.payloads.push_back(cells[i].payload);
        ++st.bricks;
        if (cells[i].constant) ++st.constant_bricks;
      } else {
        ++st.interpolated_nodes;
      }
      out.nodes.push_back(node);
    }
    e.node_count = static_cast<std::uint32_t>(out.nodes.size()) - e.first_node;
    out.levels.push_back(e);
    // Children of kept inner nodes are kept; their first child is the next index in the level
    // below.
    std::uint32_t next = static_cast<std::uint32_t>(out.nodes.size());
    for (std::size_t i = level_begin[l]; i < level_begin[l + 1]; ++i) {
      if (!kept[i]) continue;
      format::NodeType type;
      if (cells[i].subtree_constant)
        type = format::NodeType::empty, ++st.empty_nodes;
      else if (l + 1 == levels)
        type = format::NodeType::leaf;
      else
        type = format::NodeType::inner;
      std::uint32_t first = 0;
      if (type == format::NodeType::inner) {
        first = next;
        for (std::size_t k : children[i]) kept[k] = 1;
        next += static_cast<std::uint32_t>(children[i].size());
      }
      out.nodes[index[i]].child_and_type = first | (static_cast<std::uint32_t>(type) << 30);
    }
  }
}

}  // namespace

ByteBreakdown& ByteBreakdown::operator+=(const ByteBreakdown& o) {
  frame_tables += o.frame_tables;
  constant_bricks += o.constant_bricks;
  brick_headers += o.brick_headers;
  block_entries += o.block_entries;
  codes += o.codes;
  alignment += o.alignment;
  zfp_streams += o.zfp_streams;
  coarse_levels += o.coarse_levels;
  aprons_and_padding += o.aprons_and_padding;
  finest_owned_codes += o.finest_owned_codes;
  return *this;
}

FrameEncoder::FrameEncoder(const dictionary::Dictionary* dictionary, CodingSettings settings)
    : dictionary_(dictionary), settings_(settings) {
  if (settings_.codec == format::Codec::ksvd) {
    if (!dictionary_) throw InputError("the ksvd codec needs a dictionary");
    if (!format::valid_brick_size(settings_.brick_size))
      throw InputError("the brick size must be a multiple of 6 in 12..66, not " +
                       std::to_string(settings_.brick_size));
    detail::require_brick_blocks(static_cast<std::uint32_t>(dictionary_->block_size), "");
    if (dictionary_->atom_count() < 1 ||
        static_cast<std::uint32_t>(dictionary_->atom_count()) > format::dictionary_max_atoms)
      throw InputError("the dictionary has " + std::to_string(dictionary_->atom_count()) +
                       " atoms; the 16-bit atom index allows 1..65536");
    // The learned atoms before the DCT basis, when the dictionary ends with it (every container
    // dictionary does): they form the payloads' band 0.
    atoms_ = format::atom_table(
        {dictionary_->atoms.data(), static_cast<std::size_t>(dictionary_->atoms.size())},
        static_cast<std::uint32_t>(dictionary_->atom_count()));
    if (atoms_.dct_basis)
      band_split_ =
          std::min<std::uint32_t>(atoms_.count - format::dct_basis_atoms, VR_MAX_BAND_SPLIT);
    if (settings_.max_atoms < 1 || settings_.max_atoms > max_sparsity)
      throw InputError("--max-atoms must be in 1..216 (the values of a block), not " +
                       std::to_string(settings_.max_atoms));
    if (settings_.fixed_sparsity < 0 || settings_.fixed_sparsity > max_sparsity)
      throw InputError("--fixed-sparsity must be in 1..216, not " +
                       std::to_string(settings_.fixed_sparsity));
    if (settings_.fixed_sparsity == 0 &&
        !(settings_.tolerance > 0 && std::isfinite(settings_.tolerance)))
      throw InputError("the tolerance must be positive and finite");
    if (settings_.coef_bits != -1 &&
        (settings_.coef_bits < 1 || settings_.coef_bits > static_cast<int>(VR_MAX_COEF_BITS)))
      throw InputError("--coef-bits must be auto or 1..16");
    if (!(settings_.coef_step_factor > 0 && std::isfinite(settings_.coef_step_factor)))
      throw InputError("the coefficient step factor must be positive and finite");
    if (!(settings_.max_error >= 0 && std::isfinite(settings_.max_error)))
      throw InputError("--max-error must be positive and finite");
    if (settings_.mean_bits < -1 || settings_.mean_bits > static_cast<int>(VR_MEAN_BITS))
      throw InputError("--mean-bits must be auto or 0..15");
    if (!(settings_.mean_step_factor > 0 && std::isfinite(settings_.mean_step_factor)))
      throw InputError("the mean step factor must be positive and finite");
    if (settings_.fixed_sparsity == 0 && settings_.rule == VariableRateRule::lagrangian &&
        !(settings_.lagrangian_factor > 0 && std::isfinite(settings_.lagrangian_factor)))
      throw InputError("the Lagrangian factor must be positive and finite");
    if (!(settings_.level_tolerance_factor >= 1 && settings_.level_tolerance_factor <= 16))
      throw InputError("the level tolerance factor must be in [1, 16]");
    if (!(settings_.level_detail_ratio >= 0 && settings_.level_detail_ratio <= 4))
      throw InputError("the level detail ratio must be in [0, 4]");
    dictionary::SparseCodingOptions o;
    o.selection = settings_.selection;
    if (settings_.fixed_sparsity > 0) {
      o.tolerance = 0;
      o.max_atoms = settings_.fixed_sparsity;
    } else if (settings_.rule == VariableRateRule::lagrangian) {
      o.tolerance = 0;
      o.max_atoms = settings_.max_atoms;
      o.min_atom_gain = atom_gain_threshold();
    } else {
      o.tolerance = settings_.tolerance;
      o.max_atoms = settings_.max_atoms;
    }
    omp_ = std::make_shared<dictionary::BatchOmp>(dictionary_->atoms, o);
    // The basis alone, for bricks where the learned atoms do not pay (split flag: its atoms are
    // indexed from the band split, which must then be where the basis starts).
    if (settings_.split_bricks && settings_.fixed_sparsity == 0 && atoms_.dct_basis &&
        atoms_.count > format::dct_basis_atoms &&
        band_split_ == atoms_.count - format::dct_basis_atoms) {
      dct_atoms_ = dictionary_->atoms.rightCols(format::dct_basis_atoms);
      dct_omp_ = std::make_shared<dictionary::BatchOmp>(dct_atoms_, o);
    }
  } else if (!(settings_.zfp_accuracy > 0 && std::isfinite(settings_.zfp_accuracy))) {
    throw InputError("--zfp-accuracy must be positive");
  } else if (!format::valid_brick_size(settings_.brick_size)) {
    throw InputError("the brick size must be a multiple of 6 in 12..66, not " +
                     std::to_string(settings_.brick_size));
  }
}

double FrameEncoder::split_code_cost() const {
  return settings_.lagrangian_factor * static_cast<double>(VR_BLOCK_LENGTH) * settings_.tolerance *
         settings_.tolerance;
}

double FrameEncoder::atom_gain_threshold() const {
  if (settings_.codec != format::Codec::ksvd || settings_.fixed_sparsity > 0 ||
      settings_.rule != VariableRateRule::lagrangian)
    return 0;
  return split_code_cost();
}

QuantizeOptions FrameEncoder::quantize_options() const {
  QuantizeOptions o;
  o.refit = settings_.refit_quantization;
  o.orthonormal_atoms = omp_ != nullptr && omp_->orthonormal();
  o.max_atoms = settings_.max_atoms;
  o.mean_bits = settings_.mean_bits;
  o.coef_bits = settings_.coef_bits;
  o.fixed_coef_bits = fixed_rate_coef_bits;
  o.band_split = band_split_;
  if (settings_.fixed_sparsity == 0) {
    o.mean_step = settings_.mean_step_factor * settings_.tolerance;
    o.coef_step = settings_.coef_step_factor * settings_.tolerance;
  }
  if (settings_.max_error > 0) {
    // A value is off by at most its mean's error (half a step) plus what the atoms leave.
    o.mean_step =
        std::min(o.mean_step > 0 ? o.mean_step : settings_.max_error, settings_.max_error / 2);
    // The encoder's residual and the decoder's sum round differently (float): keep a margin of
    // 0.1 % of the bound for them.
    o.max_abs_error = settings_.max_error * 0.999;
  }
  if (settings_.extend_pursuit && settings_.fixed_sparsity == 0 &&
      settings_.rule == VariableRateRule::tolerance)
    o.target_energy =
        static_cast<double>(VR_BLOCK_LENGTH) * settings_.tolerance * settings_.tolerance;
  return o;
}

std::vector<std::byte> FrameEncoder::encode_brick(std::span<const float> brick) const {
  const format::BrickShape shape = this->shape();
  if (brick.size() != shape.voxels())
    throw InputError("encode_brick needs " + std::to_string(shape.voxels()) + " values (" +
                     std::to_string(shape.size) + "^3), not " + std::to_string(brick.size()));
  const auto [mn, mx] = std::minmax_element(brick.begin(), brick.end());
  if (*mn == *mx) return detail::constant_payload(*mn);
  if (settings_.codec == format::Codec::zfp)
    return detail::zfp_payload(shape, brick.data(), settings_.zfp_accuracy);
  Eigen::MatrixXf columns(VR_BLOCK_LENGTH, shape.blocks());
  std::vector<float> means(shape.blocks());
  detail::brick_to_blocks(shape, brick.data(), columns.data(), means.data());
  dictionary::SparseCodes codes, dct_codes;
  const bool learned = !dct_omp_ || settings_.learned_pursuit;
  if (learned) omp_->encode(columns, codes);
  if (dct_omp_) dct_omp_->encode(columns, dct_codes);
  detail::BrickQuantization result;
  bool dct = false;
  return quantize_either(shape, columns.data(), means.data(), learned ? &codes : nullptr,
                         dct_omp_ ? &dct_codes : nullptr, 0, dictionary_->atoms, dct_omp_.get(),
                         dct_omp_ ? &dct_atoms_ : nullptr, quantize_options(), split_code_cost(),
                         &result, &dct);
}

CodedFrame FrameEncoder::code(std::size_t t, const Volume& frame, bool keep_originals) const {
  CodedFrame coded;
  code_into(t, frame, coded, keep_originals);
  return coded;
}

void FrameEncoder::code_into(std::size_t t, const Volume& frame, CodedFrame& coded,
                             bool keep_originals) const {
  const std::size_t plane = frame.dims.plane();
  PlaneCoding options;
  options.keep_originals = keep_originals;
  code_planes(
      t, frame.dims,
      [&](std::size_t z_begin, std::size_t z_end, std::span<float> out) {
        std::copy_n(frame.data.data() + z_begin * plane, (z_end - z_begin) * plane, out.data());
      },
      coded, options);
}

void FrameEncoder::code_planes(std::size_t t, const Dims& dims,
                               const PyramidWindow::ReadPlanes& read, CodedFrame& coded,
                               const PlaneCoding& options) const {
  const bool keep_originals = options.keep_originals;
  const auto start = Clock::now();
  PyramidWindow window(format::level_geometry(
                           {static_cast<std::uint32_t>(dims.x), static_cast<std::uint32_t>(dims.y),
                            static_cast<std::uint32_t>(dims.z)},
                           shape()),
                       read, shape(), settings_.uses_level_detail());
  std::vector<float> originals = std::move(coded.originals);
  coded = CodedFrame{};
  if (keep_originals) coded.originals = std::move(originals);  // its storage, reused
  FrameStats& st = coded.stats;
  const auto lo = static_cast<float>(settings_.value_min),
             hi = static_cast<float>(settings_.value_max);
  const bool ksvd = settings_.codec == format::Codec::ksvd;
  const std::vector<format::LevelGeometry>& geometry = window.geometry();

  OctreeCells octree = octree_cells(geometry);  // 1.

  BrickCoding coding{settings_,  // 2.
                     shape(),
                     omp_.get(),
                     ksvd ? &dictionary_->atoms : nullptr,
                     dct_omp_.get(),
                     dct_omp_ ? &dct_atoms_ : nullptr,
                     quantize_options(),
                     atom_gain_threshold(),
                     geometry.size(),
                     false};
  coding.split_code_cost = ksvd ? split_code_cost() : 0;
  coding.weighted = ksvd && coding.atom_gain_threshold > 0 &&
                    (settings_.weight_owned_voxels || settings_.level_tolerance_factor != 1 ||
                     settings_.uses_level_detail());
  if (options.measure_finest && ksvd) coding.decode_atoms = atoms_;
  coding.measure_finest = options.measure_finest;
  if (options.members == 0 || options.member >= options.members)
    throw std::invalid_argument("FrameEncoder::code_planes: member " +
                                std::to_string(options.member) + " of " +
                                std::to_string(options.members));
  if (keep_originals && options.members > 1)
    throw std::invalid_argument("FrameEncoder::code_planes: a team keeps no originals");
  code_bricks(window, octree.cells, octree.level_begin, lo, hi, coding, st,
              keep_originals ? &coded.originals : nullptr, options);
  coded.window_bytes = window.peak_bytes();

  coded.t = t;
  coded.geometry = geometry;
  coded.bricks = std::move(octree.cells);
  coded.level_begin = std::move(octree.level_begin);
  if (options.members == 1) {  // 3. (a team's writer: join_team_parts)
    link_tree(coded);
    st.finest_squared_error = finest_squared_error(coded.bricks);
  }
  coded.max_abs_error = ksvd ? settings_.max_error : settings_.zfp_accuracy;

  format::FrameHeader& h = coded.header;
  h.codec = static_cast<std::uint32_t>(settings_.codec);
  h.frame_index = static_cast<std::uint32_t>(t);
  h.dims[0] = static_cast<std::uint32_t>(dims.x);
  h.dims[1] = static_cast<std::uint32_t>(dims.y);
  h.dims[2] = static_cast<std::uint32_t>(dims.z);
  h.brick_size = settings_.brick_size;
  h.block_size = ksvd ? 6 : 0;
  h.atom_count = ksvd ? static_cast<std::uint32_t>(dictionary_->atom_count()) : 0;
  h.value_min = lo;
  h.value_max = hi;
  h.codec_parameter =
      ksvd ? (settings_.fixed_sparsity > 0 ? 0.0 : settings_.tolerance) : settings_.zfp_accuracy;
  h.fixed_sparsity = static_cast<std::uint32_t>(settings_.fixed_sparsity);
  h.container_id = settings_.container_id;
  st.seconds = seconds_since(start);
}

std::vector<std::byte> FrameEncoder::write(const CodedFrame& coded, std::span<const char> keep,
                                           FrameStats* stats) const {
  if (!keep.empty() && keep.size() != coded.bricks.size())
    throw std::invalid_argument("FrameEncoder::write: one keep flag per brick");
  const auto start = Clock::now();
  FrameStats st = coded.stats;
  format::FrameContents out;  // 4.
  out.header = coded.header;
  build_node_table(coded, keep, settings_.codec == format::Codec::ksvd, shape(), out, st);
  std::vector<std::byte> bytes = format::serialize_frame(out);
  st.bytes = bytes.size();
  st.breakdown.frame_tables = st.bytes - st.breakdown.total();  // what is not a brick payload
  st.seconds += seconds_since(start);
  if (stats) *stats = st;
  return bytes;
}

std::vector<std::byte> FrameEncoder::encode(std::size_t t, const Volume& frame,
                                            FrameStats* stats) const {
  return write(code(t, frame), {}, stats);
}

namespace {

/// A team part's bytes: little-endian fields one after another (every member runs the same build),
/// written with format::detail::append_value.
template <typename T>
T take(std::span<const std::byte> in, std::size_t& at, std::size_t member) {
  if (in.size() - at < sizeof(T))
    throw std::runtime_error("the part of frame coding from team member " + std::to_string(member) +
                             " ends early, at byte " + std::to_string(at) + " of " +
                             std::to_string(in.size()));
  T value;
  std::memcpy(&value, in.data() + at, sizeof(T));
  at += sizeof(T);
  return value;
}

/// The statistics a member's bricks add up to (code_bricks), in a fixed order: the parts of the
/// coding time are summed over the team as they are over the processes of a job.
std::array<double, 10> team_statistics(const FrameStats& st) {
  return {st.seconds_pyramid,
          st.seconds_bricks,
          st.seconds_omp,
          st.seconds_quantize,
          static_cast<double>(st.blocks),
          static_cast<double>(st.codes),
          static_cast<double>(st.blocks_over_bound),
          st.unquantized_squared_error,
          st.quantized_squared_error,
          st.finest_max_error};
}

}  // namespace

std::vector<std::byte> team_part(const CodedFrame& coded, const PlaneCoding& options) {
  std::vector<std::byte> out;
  format::detail::append_value(out, std::uint64_t{coded.t});
  format::detail::append_value(out, std::uint64_t{options.member});
  format::detail::append_value(out, std::uint64_t{coded.bricks.size()});
  for (double v : team_statistics(coded.stats)) format::detail::append_value(out, v);
  for (std::size_t i = options.member; i < coded.bricks.size(); i += options.members) {
    const CodedBrick& b = coded.bricks[i];
    format::detail::append_value(out, std::uint64_t{b.codes});
    format::detail::append_value(out, b.histogram);
    format::detail::append_value(out, static_cast<std::uint8_t>(b.constant));
    format::detail::append_value(out, b.value);
    format::detail::append_value(out, b.squared_error);
    format::detail::append_value(out, b.tolerance);
    format::detail::append_value(out, std::uint64_t{b.payload.size()});
    const std::size_t at = out.size();
    out.resize(at + b.payload.size());
    if (!b.payload.empty()) std::memcpy(out.data() + at, b.payload.data(), b.payload.size());
  }
  return out;
}

void join_team_parts(CodedFrame& coded, std::span<const std::vector<std::byte>> parts,
                     const PlaneCoding& options) {
  if (parts.size() + 1 != options.members)
    throw std::invalid_argument("join_team_parts: one part from each member but the writer");
  for (std::size_t p = 0; p < parts.size(); ++p) {
    const std::size_t member = p + 1;
    const std::span<const std::byte> in = parts[p];
    std::size_t at = 0;
    const auto t = take<std::uint64_t>(in, at, member);
    const auto from = take<std::uint64_t>(in, at, member);
    const auto bricks = take<std::uint64_t>(in, at, member);
    if (t != coded.t || from != member || bricks != coded.bricks.size())
      throw std::runtime_error("team member " + std::to_string(member) + " sent frame " +
                               std::to_string(t) + " as member " + std::to_string(from) + " with " +
                               std::to_string(bricks) + " bricks; expected frame " +
                               std::to_string(coded.t) + " as member " + std::to_string(member) +
                               " with " + std::to_string(coded.bricks.size()));
    std::array<double, 10> v{};
    for (double& x : v) x = take<double>(in, at, member);
    FrameStats& st = coded.stats;
    st.seconds_pyramid += v[0];
    st.seconds_bricks += v[1];
    st.seconds_omp += v[2];
    st.seconds_quantize += v[3];
    st.blocks += static_cast<std::size_t>(v[4]);
    st.codes += static_cast<std::size_t>(v[5]);
    st.blocks_over_bound += static_cast<std::size_t>(v[6]);
    st.unquantized_squared_error += v[7];
    st.quantized_squared_error += v[8];
    st.finest_max_error = std::max(st.finest_max_error, v[9]);
    for (std::size_t i = member; i < coded.bricks.size(); i += options.members) {
      CodedBrick& b = coded.bricks[i];
      b.codes = static_cast<std::size_t>(take<std::uint64_t>(in, at, member));
      b.histogram = take<std::uint64_t>(in, at, member);
      b.constant = take<std::uint8_t>(in, at, member) != 0;
      b.value = take<float>(in, at, member);
      b.squared_error = take<double>(in, at, member);
      b.tolerance = take<double>(in, at, member);
      const auto size = take<std::uint64_t>(in, at, member);
      if (size == 0 || size > in.size() - at)
        throw std::runtime_error("team member " + std::to_string(member) + " sent brick " +
                                 std::to_string(i) + " of " + std::to_string(size) +
                                 " bytes, with " + std::to_string(in.size() - at) + " left");
      const auto first = in.begin() + static_cast<std::ptrdiff_t>(at);
      b.payload.assign(first, first + static_cast<std::ptrdiff_t>(size));
      at += static_cast<std::size_t>(size);
    }
    if (at != in.size())
      throw std::runtime_error("team member " + std::to_string(member) + " sent " +
                               std::to_string(in.size() - at) + " bytes more than its bricks");
  }
  link_tree(coded);
  coded.stats.finest_squared_error = finest_squared_error(coded.bricks);
}

}  // namespace volreel::encoder
