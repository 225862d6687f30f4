// container.hpp: the container directory `NAME.vreel/` (docs/design.md, "Container"):
// manifest.json, dictionary.bin (ksvd only) and frames/NNNNNN.vrf. The manifest is rewritten
// (atomically) after every frame with "complete": false until the last one, so an interrupted
// encode can be resumed.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "volreel/format/decoder.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/frame_file.hpp"
#include "volreel/format/source.hpp"

namespace volreel::format {

/// Version of the manifest's layout, independent of the program version.
inline constexpr std::uint32_t container_format_version = 10;

struct ManifestFrame {
  std::string file;  ///< "frames/000017.vrf", relative to the container
  std::uint64_t bytes = 0;
  std::uint32_t crc32c = 0;  ///< of the whole file
};

struct ManifestDictionary {
  std::string file = "dictionary.bin";
  std::uint64_t bytes = 0;
  std::uint32_t crc32c = 0;
  std::uint32_t atom_count = 0;
};

struct Manifest {
  std::uint32_t format_version = container_format_version;
  std::string program_version;
  std::array<std::uint32_t, 3> dims{};
  std::array<double, 3> spacing{1, 1, 1};
  std::string variable, source;
  std::vector<double> timestamps;  ///< one per frame
  /// Stored voxels per brick axis (BrickShape::size: 12..66, a multiple of 6).
  std::uint32_t brick_size = default_brick_size, brick_apron = format::brick_apron, block_size = 6;
  BrickShape shape() const { return {brick_size}; }
  std::uint32_t levels = 0;  ///< octree depth (levels, root included)
  Codec codec = Codec::ksvd;
  double tolerance = 0;              ///< ksvd ε (0 with fixed sparsity)
  std::uint32_t fixed_sparsity = 0;  ///< ksvd fixed rate S (0: variable rate)
  double zfp_accuracy = 0;
  double value_min = 0, value_max = 0;  ///< of the whole sequence (node histograms use it)
  /// The most time steps between two stored states of a node (format/SPEC.md, "Keyframes"): 1
  /// when every frame stores every node; G > 1 lets a node go without a brick for up to G − 1
  /// steps, drawn by interpolation (time_step.hpp). The first and last steps store every node.
  std::uint32_t max_keyframe_gap = 1;
  std::optional<ManifestDictionary> dictionary;
  std::vector<std::optional<ManifestFrame>> frames;  ///< one per time step; empty until written
  bool complete = false;
  nlohmann::json encoder;  ///< how it was encoded (provenance; an object, free-form inside)
  /// Binds the container's files together: every frame header and the dictionary carry it
  /// (container_identifier gives the encoder's choice).
  std::uint64_t container_id = 0;
};

/// A container's identifier: FNV-1a (64-bit) of the manifest's settings (manifest_to_json without
/// "frames", "complete", "container_id", "encoder", "program_version" and "source") and of the
/// dictionary's bytes as stored with identifier 0 — the same for the same input and settings,
/// however the input's path is spelled (so that --resume and regression checksums hold),
/// different for containers whose files must not be mixed. Never 0. `with_source`: the
/// identifier as volreel 0.1.0 wrote it before, with "source" (which verify also accepts).
std::uint64_t container_identifier(const Manifest& manifest,
                                   std::span<const std::byte> dictionary_bytes_without_id,
                                   bool with_source = false);

nlohmann::json manifest_to_json(const Manifest& manifest);
/// The text of manifest.json for `j` (manifest_to_json's object, possibly edited): `j` with its
/// "manifest_crc32c" (re)computed over the rest, one space of indent per level.
std::string manifest_text(nlohmann::json j);
/// Parses and validates (types, ranges, counts, file names); throws FormatError naming `name`
/// and the JSON field.
Manifest manifest_from_json(const std::string& text, const std::filesystem::path& name);

/// The CRC the manifest records for a file: CRC-32C of its bytes before the trailing 4-byte CRC
/// (so, when the file is intact, the value of that trailing CRC). The CRC of a whole file
/// including its own CRC is the same constant for every file, so it would detect nothing.
std::uint32_t manifest_crc(std::span<const std::byte> file_bytes);

/// "frames/000017.vrf".
std::string frame_file_name(std::size_t t);

/// Writes DIR/manifest.json atomically.
void write_manifest(const std::filesystem::path& dir, const Manifest& manifest);
/// Writes bytes to DIR/relative atomically (temporary name + rename), creating folders.
void write_container_file(const std::filesystem::path& dir, const std::string& relative,
                          std::span<const std::byte> bytes);

/// A container opened for reading: manifest parsed, dictionary loaded (ksvd), frame files read
/// (whole, or their index alone) on demand.
class Container {
 public:
  /// Throws FormatError if the manifest or dictionary is bad, or the encode is not complete
  /// (unless allow_incomplete).
  explicit Container(std::filesystem::path dir, bool allow_incomplete = false);
  /// The same, reading through `source` (local or remote).
  explicit Container(std::shared_ptr<const ContainerSource> source, bool allow_incomplete = false);

  /// The container's location: its directory, or its URL.
  const std::filesystem::path& directory() const { return dir_; }
  const ContainerSource& source() const { return *source_; }
  std::shared_ptr<const ContainerSource> shared_source() const { return source_; }
  const Manifest& manifest() const { return manifest_; }
  std::size_t frame_count() const { return manifest_.frames.size(); }
  /// The dictionary's atoms (empty for zfp).
  AtomTable atoms() const { return {atoms_, atom_count_, dct_atoms_}; }
  /// Reads frame t whole (into memory, from a folder or a server) and validates its index (header,
  /// levels, nodes, offsets); checks that it matches the manifest (size, frame index, dims, codec).
  /// Throws FormatError.
  FrameFile open_frame(std::size_t t) const;
  /// Frame t's index, validated as open_frame does, without its payloads: the index is read by
  /// range (a remote source may hand out the whole file where its cache holds it).
  FrameFile open_frame_index(std::size_t t) const;
  /// Brick b's payload of a frame opened by open_frame or open_frame_index, checked against its
  /// CRC-32C (read by range where the view holds the index alone). Throws FormatError.
  std::vector<std::byte> read_brick(const FrameView& view, std::uint32_t b) const;
  /// Every byte of the container: manifest, dictionary, frames (for bps).
  std::uint64_t total_bytes() const;

 private:
  std::shared_ptr<const ContainerSource> source_;
  std::filesystem::path dir_;
  std::uint64_t manifest_bytes_ = 0;
  Manifest manifest_;
  std::vector<float> atoms_;
  std::uint32_t atom_count_ = 0;
  bool dct_atoms_ = false;  ///< the dictionary ends with the DCT basis (flag bit 2)

  /// The checks of open_frame on a validated view of frame t.
  void check_frame(std::size_t t, const FrameView& view) const;
  /// Throws FormatError unless `found` bytes are the frame's size in the manifest.
  void check_file_size(const ManifestFrame& entry, std::uint64_t found) const;
  /// check_file_size of a local frame file's size on disk (nothing for a remote one).
  void check_local_file_size(const ManifestFrame& entry) const;
};

/// Opens the indexes of `frames` (open_frame_index) and hands each, or the message of what failed,
/// to `use` in the order given, on the calling thread: a remote container's a batch of 16 at a
/// time, each read on its own thread (each index is a round trip or two), a local one's in turn.
void for_each_frame_index(
    const Container& container, std::span<const std::size_t> frames,
    const std::function<void(std::size_t t, const FrameFile* file, const std::string& error)>& use);

/// `volreel verify`: every CRC and structure. Returns the problems found (empty: valid); calls
/// progress(done, total) after each frame if given.
std::vector<std::string> verify_container(std::shared_ptr<const ContainerSource> source,
                                          void (*progress)(std::size_t, std::size_t,
                                                           void*) = nullptr,
                                          void* user = nullptr);
/// The same for a local directory.
std::vector<std::string> verify_container(const std::filesystem::path& dir,
                                          void (*progress)(std::size_t, std::size_t,
                                                           void*) = nullptr,
                                          void* user = nullptr);

}  // namespace volreel::format
