// mosaic.hpp: a large, valid container made cheaply from a small real one, for measuring the
// player's indexing and scheduling at scale (`volreel gen mosaic`). Every frame file is real and
// passes `volreel verify` (format/SPEC.md, "Frame file", "Keyframes"), but its bricks repeat a few
// bricks of the source container: the frames are no data to look at for science.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "volreel/datasets/volume.hpp"

namespace volreel::datasets {

/// A brick of the mosaic's pool: a payload of the source container, as stored, and the 64-bin
/// histogram of its decoded values (apron included) over the source's value range.
struct MosaicBrick {
  std::vector<std::byte> payload;
  std::uint64_t histogram = 0;
};

/// Source frames the pool's bricks are drawn from (the first ones).
inline constexpr std::size_t mosaic_pool_frames = 4;
/// A node stores a brick in about one of this many frames between two keyframes.
inline constexpr std::uint64_t mosaic_stored_one_in = 4;

/// The pool of a mosaic of `source` (a container directory): up to `count` distinct brick
/// payloads of its first mosaic_pool_frames frames, the smallest first, bricks that are not a
/// constant before constant ones (a constant brick decodes to nothing worth measuring). Each is
/// decoded once (so that it is known to decode) for its histogram. Throws InputError when `source`
/// is not a container or holds no brick, format::FormatError when one of its files is bad.
std::vector<MosaicBrick> mosaic_pool(const std::filesystem::path& source, std::size_t count);

struct MosaicParams {
  std::filesystem::path source;  ///< a complete container: codec, dictionary and bricks
  std::filesystem::path out;     ///< the new container; must not exist
  std::array<std::uint32_t, 3> dims{};
  std::size_t frames = 0;
  std::uint32_t max_keyframe_gap = 8;  ///< G, as `volreel encode --max-keyframe-gap`
  std::size_t pool_bricks = 8;         ///< bricks repeated (mosaic_pool's count)
  int threads = 0;                     ///< frames written at once; 0: OpenMP's default
  std::string program_version;         ///< recorded in the manifest
};

struct MosaicReport {
  std::size_t levels = 0;
  std::size_t nodes_per_frame = 0;
  std::vector<std::size_t> pool_brick_bytes;  ///< each pool brick's payload size
  std::uint64_t bricks = 0;                   ///< stored over all frames
  std::uint64_t container_bytes = 0;          ///< every file: manifest, dictionary, frames
  double seconds = 0;
};

/// Writes the mosaic container params.out: the source's codec, dictionary (a copy carrying the new
/// container identifier), tolerance and value range at the size params.dims, params.frames frames
/// of every node of the octree (inner and leaf, no empty ones). The node (level, x, y, z) takes, in
/// keyframe stretch k = t / G, the pool brick a hash of (level, x, y, z, k) picks, so that content
/// varies in space and time. Frames 0, T − 1 and every multiple of G store every node; a frame in
/// between stores the bricks of about one node in mosaic_stored_one_in (a hash of the node and t),
/// so that no node goes more than G steps between stored states. Histograms hold each stored
/// brick's bins (a node without a brick: those of the two stored states it interpolates) and their
/// children's. Frames are written in parallel, each atomically, the manifest last ("complete":
/// true). Throws InputError naming what is wrong (the source, a size or count of 0, an existing
/// out, too many nodes); on failure, removes the partly written out.
MosaicReport write_mosaic(const MosaicParams& params, const Progress& progress = {});

}  // namespace volreel::datasets
