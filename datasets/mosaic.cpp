// mosaic.cpp: `volreel gen mosaic` — real frame files whose bricks repeat a few bricks of a small
// container, for the player's benchmarks at scale (mosaic.hpp).
#include "volreel/datasets/mosaic.hpp"

#include <omp.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <exception>
#include <optional>
#include <span>

#include "volreel/format/brick_decode.h"
#include "volreel/format/container.hpp"
#include "volreel/format/decoder.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/format/frame_file.hpp"

namespace volreel::datasets {

namespace fs = std::filesystem;

namespace {

/// A complete container at `source`, or InputError saying why not.
format::Container open_source(const fs::path& source) {
  std::error_code ec;
  if (!fs::is_directory(source, ec))
    throw InputError("mosaic source '" + source.string() +
                     "' is not a volreel container (expected a NAME.vreel directory, found " +
                     (fs::exists(source, ec) ? "a file" : "nothing") + ")");
  if (!fs::exists(source / "manifest.json", ec))
    throw InputError("mosaic source '" + source.string() +
                     "' is not a volreel container (it has no manifest.json)");
  return format::Container(source);
}

std::vector<MosaicBrick> pool_of(const format::Container& c, std::size_t count) {
  if (count == 0) throw InputError("the mosaic's pool needs at least 1 brick (got 0)");
  std::vector<format::FrameFile> files;
  for (std::size_t t = 0; t < std::min(c.frame_count(), mosaic_pool_frames); ++t)
    files.push_back(c.open_frame(t));
  struct Ref {
    std::uint64_t bytes;
    std::size_t file;
    std::uint32_t brick;
  };
  std::vector<Ref> refs;
  for (std::size_t f = 0; f < files.size(); ++f)
    for (std::uint32_t b = 0; b < files[f].view().brick_count(); ++b)
      refs.push_back({files[f].view().brick_payload_bytes(b), f, b});
  // Bricks that are not a constant first, the smallest first; ties in file order.
  std::stable_sort(refs.begin(), refs.end(), [](const Ref& a, const Ref& b) {
    const bool ca = a.bytes == 4, cb = b.bytes == 4;
    return ca != cb ? cb : a.bytes < b.bytes;
  });
  std::vector<MosaicBrick> pool;
  std::vector<float> decoded(c.manifest().shape().voxels());
  for (const Ref& r : refs) {
    if (pool.size() == count) break;
    const format::FrameView& view = files[r.file].view();
    const std::span<const std::byte> bytes = view.checked_brick_bytes(r.brick);
    // A ksvd brick codes only the blocks its position needs (its box word): the pool takes the
    // ones that code every block, which stand in for a brick anywhere.
    const vr_uint n = view.shape().blocks_per_axis();
    if (view.codec() == format::Codec::ksvd && bytes.size() != 4 &&
        (format::ksvd_box_word(bytes) & VR_BOX_BLOCKS_MASK) != vr_make_box(n, n, n))
      continue;
    if (std::any_of(pool.begin(), pool.end(), [&](const MosaicBrick& p) {
          return std::equal(p.payload.begin(), p.payload.end(), bytes.begin(), bytes.end());
        }))
      continue;
    const format::FrameHeader& h = view.header();
    format::decode_payload(bytes, view.codec(), h.codec_parameter, c.atoms(), view.shape(), decoded,
                           view.name(), view.brick_offset(r.brick));
    MosaicBrick brick;
    brick.payload.assign(bytes.begin(), bytes.end());
    for (float v : decoded)
      brick.histogram |= std::uint64_t{1} << format::histogram_bin(v, h.value_min, h.value_max);
    pool.push_back(std::move(brick));
  }
  if (pool.empty())
    throw InputError("mosaic source '" + c.directory().string() +
                     "' has no brick in its first frames to repeat (a constant one, or one that "
                     "codes all its blocks: a volume larger than one brick a side has some)");
  return pool;
}

/// SplitMix64's finalizer.
std::uint64_t mix(std::uint64_t z) {
  z += 0x9E3779B97F4A7C15ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

/// A hash of a node's place, a step or stretch, and what it decides (salt).
std::uint64_t node_hash(const format::NodePosition& p, std::uint64_t when, std::uint64_t salt) {
  std::uint64_t h = mix(salt);
  for (std::uint64_t v :
       {std::uint64_t{p.level}, std::uint64_t{p.x}, std::uint64_t{p.y}, std::uint64_t{p.z}, when})
    h = mix(h ^ v);
  return h;
}

constexpr std::uint64_t salt_brick = 0x6d6f736169632d62ull;   // "mosaic-b"
constexpr std::uint64_t salt_stored = 0x6d6f736169632d73ull;  // "mosaic-s"

/// The octree of a frame of every node (no empty ones): breadth-first, each level in Morton order
/// (a child's Morton code is its parent's times 8 plus d = a + 2b + 4c, so that visiting the
/// parents in order and their children by d gives both).
struct Tree {
  std::vector<format::LevelEntry> levels;
  std::vector<format::NodePosition> positions;
  std::vector<std::uint32_t> first_child, child_count;  ///< 0, 0 for a leaf
};

Tree build_tree(const std::array<std::uint32_t, 3>& dims, format::BrickShape shape) {
  const auto geometry = format::level_geometry(dims, shape);
  std::uint64_t nodes = 0;
  for (const auto& g : geometry) nodes += std::uint64_t{g.grid[0]} * g.grid[1] * g.grid[2];
  // The node table's child links hold 30 bits.
  if (nodes >= (std::uint64_t{1} << 30))
    throw InputError("a mosaic of " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) +
                     "x" + std::to_string(dims[2]) + " voxels would have " + std::to_string(nodes) +
                     " nodes a frame, more than a frame file holds (2^30)");
  Tree tree;
  tree.positions.push_back({0, 0, 0, 0});
  tree.levels.push_back({0, 1, {}, {}});
  for (std::uint32_t l = 0; l + 1 < geometry.size(); ++l) {
    const auto& grid = geometry[l + 1].grid;
    const format::LevelEntry parents = tree.levels[l];
    const auto first = static_cast<std::uint32_t>(tree.positions.size());
    tree.first_child.resize(tree.positions.size(), 0);
    tree.child_count.resize(tree.positions.size(), 0);
    for (std::uint32_t i = parents.first_node; i < parents.first_node + parents.node_count; ++i) {
      const format::NodePosition p = tree.positions[i];
      tree.first_child[i] = static_cast<std::uint32_t>(tree.positions.size());
      for (std::uint32_t d = 0; d < 8; ++d) {
        const std::uint32_t x = 2 * p.x + (d & 1u), y = 2 * p.y + ((d >> 1) & 1u),
                            z = 2 * p.z + (d >> 2);
        if (x >= grid[0] || y >= grid[1] || z >= grid[2]) continue;
        tree.positions.push_back({l + 1, x, y, z});
        ++tree.child_count[i];
      }
    }
    tree.levels.push_back(
        {first, static_cast<std::uint32_t>(tree.positions.size()) - first, {}, {}});
  }
  tree.first_child.resize(tree.positions.size(), 0);
  tree.child_count.resize(tree.positions.size(), 0);
  return tree;
}

/// What every frame shares: the tree, the pool, the header's constant fields, the keyframe rule.
struct MosaicFrames {
  const Tree& tree;
  const std::vector<MosaicBrick>& pool;
  format::FrameHeader header;  ///< all but frame_index (serialize_frame fills in the rest)
  std::size_t frames;
  std::uint32_t gap;

  bool keyframe(std::size_t t) const { return t == 0 || t + 1 == frames || t % gap == 0; }
  bool stored(const format::NodePosition& p, std::size_t t) const {
    return keyframe(t) || node_hash(p, t, salt_stored) % mosaic_stored_one_in == 0;
  }
  std::uint32_t brick(const format::NodePosition& p, std::size_t t) const {
    return static_cast<std::uint32_t>(node_hash(p, t / gap, salt_brick) % pool.size());
  }

  format::FrameContents contents(std::size_t t) const {
    const std::size_t n = tree.positions.size();
    std::vector<std::uint32_t> pick(n, format::no_brick);
    std::vector<std::uint64_t> histogram(n, 0);
    for (std::size_t i = 0; i < n; ++i) {
      const format::NodePosition& p = tree.positions[i];
      if (stored(p, t)) {
        pick[i] = brick(p, t);
        histogram[i] = pool[pick[i]].histogram;
        continue;
      }
      // Interpolated between the stored states s < t < u: the bins of both (s is in t's stretch,
      // since the stretch's first frame stores every node).
      std::size_t u = t + 1;
      while (!stored(p, u)) ++u;
      histogram[i] = pool[brick(p, t)].histogram | pool[brick(p, u)].histogram;
    }
    // Every histogram holds its children's (children come after their parent).
    for (std::size_t i = n; i-- > 0;)
      for (std::uint32_t c = 0; c < tree.child_count[i]; ++c)
        histogram[i] |= histogram[tree.first_child[i] + c];
    format::FrameContents f;
    f.header = header;
    f.header.frame_index = static_cast<std::uint32_t>(t);
    f.levels = tree.levels;
    f.nodes.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      format::Node& node = f.nodes[i];
      const bool inner = tree.child_count[i] > 0;
      node.brick = pick[i] == format::no_brick ? format::no_brick
                                               : static_cast<std::uint32_t>(f.payloads.size());
      node.child_and_type =
          inner ? tree.first_child[i] : static_cast<std::uint32_t>(format::NodeType::leaf) << 30;
      node.histogram = histogram[i];
      if (pick[i] != format::no_brick) f.payloads.push_back(pool[pick[i]].payload);
    }
    return f;
  }
};

std::string hex(std::uint64_t v) {
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(v));
  return text;
}

}  // namespace

std::vector<MosaicBrick> mosaic_pool(const fs::path& source, std::size_t count) {
  return pool_of(open_source(source), count);
}

MosaicReport write_mosaic(const MosaicParams& params, const Progress& progress) {
  const auto start = std::chrono::steady_clock::now();
  for (std::size_t a = 0; a < 3; ++a)
    if (params.dims[a] == 0 || params.dims[a] > (1u << 24))
      throw InputError("the mosaic's size must be 1..16777216 voxels on each axis (got " +
                       std::to_string(params.dims[0]) + "x" + std::to_string(params.dims[1]) + "x" +
                       std::to_string(params.dims[2]) + ")");
  if (params.frames == 0) throw InputError("the mosaic needs at least 1 frame (got 0)");
  if (params.frames > 100000000)
    throw InputError("the mosaic can have at most 100000000 frames (got " +
                     std::to_string(params.frames) + ")");
  if (params.max_keyframe_gap < 1 || params.max_keyframe_gap > 65535)
    throw InputError("the maximum keyframe gap must be 1..65535 (got " +
                     std::to_string(params.max_keyframe_gap) + ")");
  if (params.out.empty()) throw InputError("the mosaic needs an output directory");
  std::error_code ec;
  if (fs::exists(fs::symlink_status(params.out, ec)))
    throw InputError("'" + params.out.string() +
                     "' already exists: volreel gen mosaic writes a new container and never "
                     "replaces anything; remove it or give another output directory");

  const format::Container source = open_source(params.source);
  const format::Manifest& from = source.manifest();
  const std::vector<MosaicBrick> pool = pool_of(source, params.pool_bricks);
  const Tree tree = build_tree(params.dims, from.shape());

  // The manifest: the source's coding at the mosaic's size and length.
  format::Manifest m;
  m.program_version = params.program_version;
  m.dims = params.dims;
  m.spacing = from.spacing;
  m.variable = from.variable;
  m.source = "mosaic of the bricks of container " + hex(from.container_id) + " (" + from.source +
             "), for benchmarks";
  for (std::size_t t = 0; t < params.frames; ++t) m.timestamps.push_back(static_cast<double>(t));
  m.block_size = from.block_size;
  m.brick_size = from.brick_size;
  m.levels = static_cast<std::uint32_t>(tree.levels.size());
  m.codec = from.codec;
  m.tolerance = from.tolerance;
  m.fixed_sparsity = from.fixed_sparsity;
  m.zfp_accuracy = from.zfp_accuracy;
  m.value_min = from.value_min;
  m.value_max = from.value_max;
  m.max_keyframe_gap = params.max_keyframe_gap;
  m.frames.assign(params.frames, std::nullopt);
  m.complete = false;
  m.encoder = from.encoder;
  m.encoder["mosaic"] = {{"from", params.source.string()},
                         {"from_container_id", hex(from.container_id)},
                         {"pool_bricks", pool.size()},
                         {"pool_frames", std::min(from.frames.size(), mosaic_pool_frames)},
                         {"stored_one_in", mosaic_stored_one_in}};
  // The dictionary as the source stores it, under the new identifier.
  std::optional<format::DictionaryFile> dictionary;
  std::vector<std::byte> dictionary_bytes;
  if (from.dictionary) {
    dictionary = format::parse_dictionary_file(
        source.source().read_file(from.dictionary->file, format::detail::max_dictionary_bytes),
        source.source().name(from.dictionary->file));
    dictionary->container_id = 0;
    dictionary_bytes = format::serialize_dictionary_file(*dictionary);
  }
  m.container_id = format::container_identifier(m, dictionary_bytes);
  if (dictionary) {
    dictionary->container_id = m.container_id;
    dictionary_bytes = format::serialize_dictionary_file(*dictionary);
    m.dictionary =
        format::ManifestDictionary{"dictionary.bin", dictionary_bytes.size(),
                                   format::manifest_crc(dictionary_bytes), dictionary->atom_count};
  }

  format::FrameHeader header{};
  header.codec = static_cast<std::uint32_t>(m.codec);
  for (std::size_t a = 0; a < 3; ++a) header.dims[a] = m.dims[a];
  header.brick_size = m.brick_size;
  header.block_size = m.block_size;
  header.atom_count = m.dictionary ? m.dictionary->atom_count : 0;
  header.value_min = static_cast<float>(m.value_min);
  header.value_max = static_cast<float>(m.value_max);
  header.codec_parameter = m.codec == format::Codec::zfp ? m.zfp_accuracy
                           : m.fixed_sparsity > 0        ? 0.0
                                                         : m.tolerance;
  header.fixed_sparsity = m.fixed_sparsity;
  header.container_id = m.container_id;
  const MosaicFrames frames{tree, pool, header, params.frames, params.max_keyframe_gap};

  MosaicReport report;
  report.levels = tree.levels.size();
  report.nodes_per_frame = tree.positions.size();
  for (const MosaicBrick& b : pool) report.pool_brick_bytes.push_back(b.payload.size());

  fs::create_directories(params.out / "frames", ec);
  if (ec)
    throw InputError("cannot create '" + (params.out / "frames").string() + "': " + ec.message());
  try {
    if (dictionary) format::write_container_file(params.out, "dictionary.bin", dictionary_bytes);
    std::atomic<bool> failed{false};
    std::exception_ptr error;
    std::atomic<std::uint64_t> bricks{0};
    const int threads = params.threads > 0 ? params.threads : std::max(1, omp_get_max_threads());
    // A few frames a thread at a time, the progress reported between them, outside the parallel
    // region (a progress callback may throw: an interruption).
    const std::size_t chunk = 4 * static_cast<std::size_t>(threads);
    for (std::size_t first = 0; first < params.frames; first += chunk) {
      const auto begin = static_cast<std::ptrdiff_t>(first);
      const auto end = static_cast<std::ptrdiff_t>(std::min(params.frames, first + chunk));
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
      for (std::ptrdiff_t i = begin; i < end; ++i) {
        if (failed.load()) continue;
        const auto t = static_cast<std::size_t>(i);
        try {
          const format::FrameContents contents = frames.contents(t);
          const std::vector<std::byte> bytes = format::serialize_frame(contents);
          // Never write a frame a reader would refuse (its payloads are the pool's, decoded
          // above).
          const format::FrameView check(bytes, format::frame_file_name(t));
          format::write_container_file(params.out, format::frame_file_name(t), bytes);
          m.frames[t] = format::ManifestFrame{format::frame_file_name(t), bytes.size(),
                                              format::manifest_crc(bytes)};
          bricks += contents.payloads.size();
        } catch (...) {
#pragma omp critical(volreel_mosaic_error)
          if (!error) error = std::current_exception();
          failed = true;
        }
      }
      if (error) std::rethrow_exception(error);
      progress.report(static_cast<double>(end), static_cast<double>(params.frames));
    }
    m.complete = true;
    format::write_manifest(params.out, m);
    report.bricks = bricks.load();
  } catch (...) {
    fs::remove_all(params.out, ec);  // it did not exist before
    throw;
  }
  report.container_bytes = format::Container(params.out).total_bytes();
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

}  // namespace volreel::datasets
