// container.cpp: manifest.json, the container reader and verify.
#include "volreel/format/container.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <thread>
#include <unordered_set>

#include "volreel/format/brick_decode.h"
#include "volreel/format/crc32c.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/format/json_input.hpp"
#include "volreel/format/time_step.hpp"

namespace volreel::format {

namespace fs = std::filesystem;
using nlohmann::json;

std::uint32_t manifest_crc(std::span<const std::byte> file_bytes) {
  return file_bytes.size() < 4 ? 0 : crc32c(file_bytes.first(file_bytes.size() - 4));
}

std::string frame_file_name(std::size_t t) {
  char name[32];
  std::snprintf(name, sizeof name, "frames/%06zu.vrf", t);
  return name;
}

namespace {

std::string id_text(std::uint64_t id) {
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(id));
  return text;
}

std::string dims_text(const std::array<std::uint32_t, 3>& dims) {
  return std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]);
}

/// The manifest's checksum: CRC-32C of its compact serialization without "manifest_crc32c" (the
/// parser gives back the same numbers and strings, so the reader recomputes it exactly).
std::uint32_t manifest_checksum(const json& j) {
  const std::string text = j.dump(-1, ' ', false, json::error_handler_t::replace);
  return crc32c(std::as_bytes(std::span(text.data(), text.size())));
}

}  // namespace

json manifest_to_json(const Manifest& m) {
  json frames = json::array();
  for (const auto& f : m.frames)
    frames.push_back(f ? json{{"file", f->file}, {"bytes", f->bytes}, {"crc32c", f->crc32c}}
                       : json(nullptr));
  json j{{"format", "volreel-container"},
         {"format_version", m.format_version},
         {"program_version", m.program_version},
         {"dims", m.dims},
         {"spacing", m.spacing},
         {"variable", m.variable},
         {"source", m.source},
         {"frame_count", m.frames.size()},
         {"timestamps", m.timestamps},
         {"brick_size", m.brick_size},
         {"brick_apron", m.brick_apron},
         {"block_size", m.block_size},
         {"levels", m.levels},
         {"codec", m.codec == Codec::ksvd ? "ksvd" : "zfp"},
         {"tolerance", m.tolerance},
         {"fixed_sparsity", m.fixed_sparsity},
         {"zfp_accuracy", m.zfp_accuracy},
         {"value_range", {m.value_min, m.value_max}},
         {"max_keyframe_gap", m.max_keyframe_gap},
         {"dictionary", m.dictionary ? json{{"file", m.dictionary->file},
                                            {"bytes", m.dictionary->bytes},
                                            {"crc32c", m.dictionary->crc32c},
                                            {"atom_count", m.dictionary->atom_count}}
                                     : json(nullptr)},
         {"frames", frames},
         {"complete", m.complete},
         {"encoder", m.encoder},
         {"container_id", id_text(m.container_id)}};
  return j;
}

std::uint64_t container_identifier(const Manifest& manifest,
                                   std::span<const std::byte> dictionary_bytes_without_id,
                                   bool with_source) {
  json j = manifest_to_json(manifest);
  for (const char* field : {"frames", "complete", "container_id", "encoder", "program_version"})
    j.erase(field);
  if (!with_source) j.erase("source");
  const std::string text = j.dump(-1, ' ', false, json::error_handler_t::replace);
  std::uint64_t h = 0xCBF29CE484222325u;  // FNV-1a, 64-bit
  const auto mix = [&](std::span<const std::byte> bytes) {
    for (std::byte b : bytes) h = (h ^ static_cast<std::uint64_t>(b)) * 0x100000001B3u;
  };
  mix(std::as_bytes(std::span(text.data(), text.size())));
  mix(dictionary_bytes_without_id);
  return h == 0 ? 1 : h;
}

Manifest manifest_from_json(const std::string& text, const fs::path& name) {
  json j = parse_json_document(text, name, false);
  const auto fail = [&](const std::string& field, const std::string& expected, const json& found) {
    throw FormatError(name, FormatError::no_offset, "\"" + field + "\": " + expected,
                      found.is_null() ? "nothing" : describe_json(found));
  };
  if (!j.is_object()) fail("(top level)", "an object", j);
  // The version first (an older container has no checksum), then the checksum over the rest.
  {
    const auto version = j.find("format_version");
    if (version != j.end() && version->is_number_unsigned() &&
        version->get<std::uint64_t>() < container_format_version)
      fail("format_version",
           std::to_string(container_format_version) +
               " (a container of an older volreel: encode the series again)",
           *version);
    const auto stored = j.find("manifest_crc32c");
    if (stored == j.end() || !stored->is_number_unsigned() ||
        stored->get<std::uint64_t>() > 0xFFFFFFFFu)
      fail("manifest_crc32c", "a 32-bit integer",
           stored == j.end() ? json(nullptr) : json(*stored));
    const auto expected = stored->get<std::uint32_t>();
    j.erase("manifest_crc32c");
    const std::uint32_t found = manifest_checksum(j);
    if (found != expected)
      throw FormatError(name, FormatError::no_offset,
                        "\"manifest_crc32c\": " + std::to_string(expected) +
                            ", the CRC-32C of the rest of the manifest",
                        std::to_string(found) + " (manifest.json is corrupt or was edited)");
  }
  const auto get = [&](const char* field) -> const json& {
    static const json null;
    auto it = j.find(field);
    return it == j.end() ? null : *it;
  };
  const auto uint_field = [&](const char* field, std::uint64_t lo, std::uint64_t hi) {
    const json& v = get(field);
    if (!v.is_number_unsigned() || v.get<std::uint64_t>() < lo || v.get<std::uint64_t>() > hi)
      fail(field, "an integer in " + std::to_string(lo) + ".." + std::to_string(hi), v);
    return v.get<std::uint64_t>();
  };
  const auto number_field = [&](const char* field) {
    const json& v = get(field);
    if (!v.is_number() || !std::isfinite(v.get<double>())) fail(field, "a finite number", v);
    return v.get<double>();
  };
  const auto string_field = [&](const char* field) {
    const json& v = get(field);
    if (!v.is_string()) fail(field, "a string", v);
    return v.get<std::string>();
  };
  Manifest m;
  if (get("format") != "volreel-container") fail("format", "\"volreel-container\"", get("format"));
  m.format_version = static_cast<std::uint32_t>(uint_field("format_version", 1, 1000000));
  if (m.format_version != container_format_version)
    fail("format_version",
         std::to_string(container_format_version) +
             (m.format_version < container_format_version
                  ? " (a container of an older volreel: encode the series again)"
                  : ""),
         get("format_version"));
  m.program_version = string_field("program_version");
  const json& dims = get("dims");
  if (!dims.is_array() || dims.size() != 3) fail("dims", "[x, y, z]", dims);
  for (std::size_t a = 0; a < 3; ++a) {
    if (!dims[a].is_number_unsigned() || dims[a].get<std::uint64_t>() == 0 ||
        dims[a].get<std::uint64_t>() > (1u << 24))
      fail("dims", "three integers in 1..16777216", dims);
    m.dims[a] = dims[a].get<std::uint32_t>();
  }
  const json& spacing = get("spacing");
  if (!spacing.is_array() || spacing.size() != 3) fail("spacing", "[sx, sy, sz]", spacing);
  for (std::size_t a = 0; a < 3; ++a) {
    if (!spacing[a].is_number() || !(spacing[a].get<double>() > 0))
      fail("spacing", "three positive numbers", spacing);
    m.spacing[a] = spacing[a].get<double>();
  }
  m.variable = string_field("variable");
  m.source = string_field("source");
  const std::size_t frame_count = uint_field("frame_count", 1, 100000000);
  const json& timestamps = get("timestamps");
  if (!timestamps.is_array() || timestamps.size() != frame_count)
    fail("timestamps", "an array of frame_count = " + std::to_string(frame_count) + " numbers",
         timestamps.is_array() ? json(timestamps.size()) : timestamps);
  for (const json& t : timestamps) {
    if (!t.is_number() || !std::isfinite(t.get<double>())) fail("timestamps", "finite numbers", t);
    if (!m.timestamps.empty() && !(t.get<double>() > m.timestamps.back()))
      fail("timestamps", "increasing numbers", t);
    m.timestamps.push_back(t.get<double>());
  }
  m.brick_size =
      static_cast<std::uint32_t>(uint_field("brick_size", min_brick_size, max_brick_size));
  if (!valid_brick_size(m.brick_size))
    fail("brick_size", "a multiple of 6 in 12..66", get("brick_size"));
  m.brick_apron = static_cast<std::uint32_t>(uint_field("brick_apron", brick_apron, brick_apron));
  m.levels = static_cast<std::uint32_t>(uint_field("levels", 1, max_levels));
  if (m.levels != level_geometry(m.dims, m.shape()).size())
    fail("levels", std::to_string(level_geometry(m.dims, m.shape()).size()) + " for these dims",
         get("levels"));
  const std::string codec = string_field("codec");
  if (codec == "ksvd")
    m.codec = Codec::ksvd;
  else if (codec == "zfp")
    m.codec = Codec::zfp;
  else
    fail("codec", "\"ksvd\" or \"zfp\"", get("codec"));
  const bool ksvd = m.codec == Codec::ksvd;
  m.block_size = static_cast<std::uint32_t>(ksvd ? uint_field("block_size", 6, 6)
                                                 : uint_field("block_size", 0, 0));
  m.fixed_sparsity = static_cast<std::uint32_t>(uint_field("fixed_sparsity", 0, ksvd ? 216 : 0));
  m.tolerance = number_field("tolerance");
  if (ksvd && m.fixed_sparsity == 0 ? !(m.tolerance > 0) : m.tolerance != 0)
    fail("tolerance",
         ksvd && m.fixed_sparsity == 0 ? "a positive number (variable rate)"
                                       : "0 (fixed rate or zfp)",
         get("tolerance"));
  m.zfp_accuracy = number_field("zfp_accuracy");
  if (ksvd ? m.zfp_accuracy != 0 : !(m.zfp_accuracy > 0))
    fail("zfp_accuracy", ksvd ? "0 (ksvd codec)" : "a positive number", get("zfp_accuracy"));
  const json& range = get("value_range");
  const double largest_float = static_cast<double>(std::numeric_limits<float>::max());
  if (!range.is_array() || range.size() != 2 || !range[0].is_number() || !range[1].is_number() ||
      !(range[0].get<double>() <= range[1].get<double>()) ||
      !(std::abs(range[0].get<double>()) <= largest_float) ||
      !(std::abs(range[1].get<double>()) <= largest_float))
    fail("value_range", "[min, max] with min <= max, both within float32's range", range);
  m.value_min = range[0].get<double>();
  m.value_max = range[1].get<double>();
  m.max_keyframe_gap = static_cast<std::uint32_t>(uint_field("max_keyframe_gap", 1, 65535));
  const json& dict = get("dictionary");
  if (m.codec == Codec::ksvd) {
    if (!dict.is_object()) fail("dictionary", "an object (ksvd codec)", dict);
    ManifestDictionary d;
    if (!dict.contains("file") || dict["file"] != "dictionary.bin")
      fail("dictionary.file", "\"dictionary.bin\"", dict.value("file", json()));
    if (!dict.contains("bytes") || !dict["bytes"].is_number_unsigned())
      fail("dictionary.bytes", "an integer", dict.value("bytes", json()));
    if (!dict.contains("crc32c") || !dict["crc32c"].is_number_unsigned() ||
        dict["crc32c"].get<std::uint64_t>() > 0xFFFFFFFFu)
      fail("dictionary.crc32c", "a 32-bit integer", dict.value("crc32c", json()));
    if (!dict.contains("atom_count") || !dict["atom_count"].is_number_unsigned() ||
        dict["atom_count"].get<std::uint64_t>() == 0 ||
        dict["atom_count"].get<std::uint64_t>() > dictionary_max_atoms)
      fail("dictionary.atom_count", "an integer in 1.." + std::to_string(dictionary_max_atoms),
           dict.value("atom_count", json()));
    d.bytes = dict["bytes"].get<std::uint64_t>();
    d.crc32c = dict["crc32c"].get<std::uint32_t>();
    d.atom_count = dict["atom_count"].get<std::uint32_t>();
    m.dictionary = d;
  } else if (!dict.is_null()) {
    fail("dictionary", "null (zfp codec)", dict);
  }
  const json& frames = get("frames");
  if (!frames.is_array() || frames.size() != frame_count)
    fail("frames", "an array of frame_count = " + std::to_string(frame_count) + " entries",
         frames.is_array() ? json(frames.size()) : frames);
  for (std::size_t t = 0; t < frame_count; ++t) {
    const json& f = frames[t];
    const std::string field = "frames[" + std::to_string(t) + "]";
    if (f.is_null()) {
      m.frames.emplace_back();
      continue;
    }
    if (!f.is_object() || f.value("file", json()) != frame_file_name(t))
      fail(field + ".file", "\"" + frame_file_name(t) + "\"",
           f.is_object() ? f.value("file", json()) : f);
    if (!f.contains("bytes") || !f["bytes"].is_number_unsigned())
      fail(field + ".bytes", "an integer", f.value("bytes", json()));
    if (!f.contains("crc32c") || !f["crc32c"].is_number_unsigned() ||
        f["crc32c"].get<std::uint64_t>() > 0xFFFFFFFFu)
      fail(field + ".crc32c", "a 32-bit integer", f.value("crc32c", json()));
    m.frames.push_back(ManifestFrame{frame_file_name(t), f["bytes"].get<std::uint64_t>(),
                                     f["crc32c"].get<std::uint32_t>()});
  }
  const json& complete = get("complete");
  if (!complete.is_boolean()) fail("complete", "true or false", complete);
  m.complete = complete.get<bool>();
  m.encoder = get("encoder");
  if (!m.encoder.is_object())
    fail("encoder", "an object (how the container was encoded)", m.encoder);
  const json& id = get("container_id");
  if (!id.is_string() || id.get_ref<const std::string&>().size() != 16 ||
      id.get_ref<const std::string&>().find_first_not_of("0123456789abcdef") != std::string::npos)
    fail("container_id", "16 lowercase hexadecimal digits", id);
  m.container_id = std::stoull(id.get<std::string>(), nullptr, 16);
  if (m.container_id == 0) fail("container_id", "a nonzero identifier", id);
  return m;
}

void write_container_file(const fs::path& dir, const std::string& relative,
                          std::span<const std::byte> bytes) {
  const fs::path path = dir / relative;
  std::error_code ec;
  fs::create_directories(path.parent_path(), ec);
  if (ec) throw FormatError(path.parent_path(), "cannot create directory: " + ec.message());
  detail::write_file_atomically(path, bytes);
}

std::string manifest_text(json j) {
  j.erase("manifest_crc32c");
  j["manifest_crc32c"] = manifest_checksum(j);
  return j.dump(1, ' ', false, json::error_handler_t::replace) + "\n";
}

void write_manifest(const fs::path& dir, const Manifest& manifest) {
  const std::string text = manifest_text(manifest_to_json(manifest));
  write_container_file(dir, "manifest.json", std::as_bytes(std::span(text.data(), text.size())));
}

Container::Container(fs::path dir, bool allow_incomplete)
    : Container(std::make_shared<LocalSource>(std::move(dir)), allow_incomplete) {}

Container::Container(std::shared_ptr<const ContainerSource> source, bool allow_incomplete)
    : source_(std::move(source)), dir_(source_->location()) {
  const fs::path manifest_path = source_->name("manifest.json");
  const auto bytes = source_->read_file("manifest.json", detail::max_json_bytes);
  manifest_bytes_ = bytes.size();
  manifest_ = manifest_from_json(
      std::string(reinterpret_cast<const char*>(bytes.data()), bytes.size()), manifest_path);
  if (!manifest_.complete && !allow_incomplete)
    throw FormatError(
        manifest_path,
        "the encode is not complete (\"complete\": false); resume it with volreel encode --resume");
  if (manifest_.dictionary) {
    const fs::path dict_path = source_->name(manifest_.dictionary->file);
    auto kept = source_->kept(manifest_.dictionary->file, 0);
    const bool from_cache = kept.has_value();
    const std::vector<std::byte> dict_bytes =
        kept ? std::move(*kept)
             : source_->read_file(manifest_.dictionary->file, detail::max_dictionary_bytes);
    const DictionaryFile d = parse_dictionary_file(dict_bytes, dict_path);
    if (d.block_size != 6)
      throw FormatError(dict_path, 20, "block size 6", std::to_string(d.block_size));
    if (d.atom_count != manifest_.dictionary->atom_count)
      throw FormatError(dict_path, 16,
                        std::to_string(manifest_.dictionary->atom_count) + " atoms (manifest.json)",
                        std::to_string(d.atom_count));
    if (d.container_id != manifest_.container_id)
      throw FormatError(
          dict_path, offsetof(DictionaryFileHeader, container_id),
          "container identifier " + id_text(manifest_.container_id) + " (manifest.json)",
          id_text(d.container_id) + " (the dictionary of another container)");
    atoms_ = d.atoms;
    atom_count_ = d.atom_count;
    dct_atoms_ = d.dct_atoms;
    if (!from_cache) source_->keep(manifest_.dictionary->file, 0, dict_bytes);
  }
}

namespace {

/// The manifest's entry of frame t; throws FormatError if there is none.
const ManifestFrame& manifest_frame(const Manifest& m, const ContainerSource& source,
                                    std::size_t t) {
  if (t >= m.frames.size())
    throw FormatError(source.location(), "no frame " + std::to_string(t) + " (the container has " +
                                             std::to_string(m.frames.size()) + ")");
  if (!m.frames[t])
    throw FormatError(source.name("manifest.json"),
                      "frame " + std::to_string(t) + " has not been written");
  return *m.frames[t];
}

/// What a remote reader fetches first of a frame file to find its index: the whole index of a
/// frame of up to about 150 nodes in one request (a 256³ volume's), the rest in a second.
constexpr std::uint64_t first_index_read = 4096;

}  // namespace

void Container::check_file_size(const ManifestFrame& entry, std::uint64_t found) const {
  if (found == entry.bytes) return;
  const bool local = source_->local_directory().has_value();
  throw FormatError(
      source_->name(entry.file), FormatError::no_offset,
      std::to_string(entry.bytes) + " bytes (its size in manifest.json)",
      std::to_string(found) +
          (found > entry.bytes ? " (the file was replaced after the container was written)"
           : local             ? " (the file was cut short after the container was written)"
                               : " (the server's answer was cut short, or the file changed on "
                                 "the server after the container was written)"));
}

void Container::check_local_file_size(const ManifestFrame& entry) const {
  if (!source_->local_directory()) return;
  std::error_code ec;
  const std::uintmax_t size = fs::file_size(source_->name(entry.file), ec);
  if (!ec) check_file_size(entry, size);  // one that cannot be read is named by the read
}

FrameFile Container::open_frame(std::size_t t) const {
  const ManifestFrame& entry = manifest_frame(manifest_, *source_, t);
  const fs::path path = source_->name(entry.file);
  // Read, not memory-mapped: a mapped file that shrinks (cut short, or rewritten in place) under
  // a reader ends it with SIGBUS, and a reader may be a Python or ParaView session that holds a
  // frame for as long as it likes. A local file's size is checked before it is read.
  check_local_file_size(entry);
  std::vector<std::byte> bytes = source_->read_file(entry.file, entry.bytes);
  check_file_size(entry, bytes.size());  // before the header's checks, which would blame the format
  const std::uint64_t size = bytes.size();
  FrameFile file(std::move(bytes), path, size);
  check_frame(t, file.view());
  return file;
}

FrameFile Container::open_frame_index(std::size_t t) const {
  const ManifestFrame& entry = manifest_frame(manifest_, *source_, t);
  const fs::path path = source_->name(entry.file);
  check_local_file_size(entry);  // a file cut short past its index is found here too
  if (auto kept = source_->kept(entry.file, 0)) {
    FrameFile file(std::move(*kept), path, entry.bytes);
    check_frame(t, file.view());
    return file;
  }
  std::vector<std::byte> bytes =
      source_->read_range(entry.file, 0, std::min(entry.bytes, first_index_read));
  if (bytes.size() >= sizeof(FrameHeader)) {
    // The index ends where the payloads begin (the header's payload_offset); an offset beyond the
    // file is left to the view's checks.
    std::uint64_t payload_offset = 0;
    std::memcpy(&payload_offset, bytes.data() + offsetof(FrameHeader, payload_offset), 8);
    if (payload_offset > bytes.size() && payload_offset <= entry.bytes) {
      const std::vector<std::byte> rest =
          source_->read_range(entry.file, bytes.size(), payload_offset - bytes.size());
      bytes.insert(bytes.end(), rest.begin(), rest.end());
    } else if (payload_offset >= sizeof(FrameHeader) && payload_offset < bytes.size()) {
      bytes.resize(payload_offset);  // the index alone (payloads are read and checked by brick)
    }
  }
  FrameFile file(std::move(bytes), path, entry.bytes);
  check_frame(t, file.view());
  source_->keep(entry.file, 0, file.view().bytes());
  return file;
}

void for_each_frame_index(const Container& container, std::span<const std::size_t> frames,
                          const std::function<void(std::size_t t, const FrameFile* file,
                                                   const std::string& error)>& use) {
  const std::size_t batch = container.source().local_directory() ? 1 : 16;
  std::vector<std::optional<FrameFile>> files(batch);
  std::vector<std::string> errors(batch);
  for (std::size_t first = 0; first < frames.size(); first += batch) {
    const std::size_t end = std::min(frames.size(), first + batch);
    const auto open = [&](std::size_t i) {
      try {
        files[i - first].emplace(container.open_frame_index(frames[i]));
      } catch (const std::exception& e) {
        errors[i - first] = e.what();
      }
    };
    if (batch == 1) {
      open(first);
    } else {
      std::vector<std::thread> threads;
      for (std::size_t i = first; i < end; ++i) threads.emplace_back(open, i);
      for (std::thread& th : threads) th.join();
    }
    for (std::size_t i = first; i < end; ++i) {
      use(frames[i], files[i - first] ? &*files[i - first] : nullptr, errors[i - first]);
      files[i - first].reset();
      errors[i - first].clear();
    }
  }
}

std::vector<std::byte> Container::read_brick(const FrameView& view, std::uint32_t b) const {
  if (view.has_payloads()) {
    const std::span<const std::byte> payload = view.checked_brick_bytes(b);
    return {payload.begin(), payload.end()};
  }
  const ManifestFrame& entry = manifest_frame(manifest_, *source_, view.header().frame_index);
  std::vector<std::byte> payload =
      source_->read_range(entry.file, view.brick_offset(b), view.brick_payload_bytes(b));
  const std::uint32_t found = crc32c(payload), expected = view.brick_crc(b);
  if (found != expected)
    throw FormatError(view.name(), view.brick_offset(b),
                      "brick " + std::to_string(b) + " payload of CRC-32C " +
                          std::to_string(expected) + " (the frame's index)",
                      std::to_string(found) + " (payload corrupt)");
  return payload;
}

void Container::check_frame(std::size_t t, const FrameView& view) const {
  const ManifestFrame& entry = *manifest_.frames[t];
  const fs::path& path = view.name();
  const FrameHeader& h = view.header();
  if (view.file_size() != entry.bytes)
    throw FormatError(path, FormatError::no_offset,
                      std::to_string(entry.bytes) + " bytes (manifest.json)",
                      std::to_string(view.file_size()));
  if (h.container_id != manifest_.container_id)
    throw FormatError(
        path, offsetof(FrameHeader, container_id),
        "container identifier " + id_text(manifest_.container_id) + " (manifest.json)",
        id_text(h.container_id) + " (a frame of another container)");
  if (h.frame_index != t)
    throw FormatError(path, offsetof(FrameHeader, frame_index), "frame index " + std::to_string(t),
                      std::to_string(h.frame_index));
  if (h.dims[0] != manifest_.dims[0] || h.dims[1] != manifest_.dims[1] ||
      h.dims[2] != manifest_.dims[2])
    throw FormatError(path, offsetof(FrameHeader, dims),
                      "dims " + dims_text(manifest_.dims) + " (manifest.json)",
                      dims_text({h.dims[0], h.dims[1], h.dims[2]}));
  if (static_cast<Codec>(h.codec) != manifest_.codec)
    throw FormatError(path, offsetof(FrameHeader, codec), "the manifest's codec", "another");
  if (h.value_min != static_cast<float>(manifest_.value_min) ||
      h.value_max != static_cast<float>(manifest_.value_max))
    throw FormatError(path, offsetof(FrameHeader, value_min),
                      "the manifest's value range [" + number_text(manifest_.value_min) + ", " +
                          number_text(manifest_.value_max) + "]",
                      "[" + number_text(h.value_min) + ", " + number_text(h.value_max) + "]");
  if (h.fixed_sparsity != manifest_.fixed_sparsity)
    throw FormatError(
        path, offsetof(FrameHeader, fixed_sparsity),
        "fixed sparsity " + std::to_string(manifest_.fixed_sparsity) + " (manifest.json)",
        std::to_string(h.fixed_sparsity));
  if (h.brick_size != manifest_.brick_size)
    throw FormatError(path, offsetof(FrameHeader, brick_size),
                      "brick size " + std::to_string(manifest_.brick_size) + " (manifest.json)",
                      std::to_string(h.brick_size));
  if (h.block_size != manifest_.block_size)
    throw FormatError(path, offsetof(FrameHeader, block_size),
                      "block size " + std::to_string(manifest_.block_size) + " (manifest.json)",
                      std::to_string(h.block_size));
  // ε of a ksvd frame: the manifest's, or smaller for a frame coded again for a PSNR target.
  const double parameter = h.codec_parameter;
  const bool parameter_ok = manifest_.codec == Codec::zfp ? parameter == manifest_.zfp_accuracy
                            : manifest_.fixed_sparsity > 0
                                ? parameter == 0
                                : parameter > 0 && parameter <= manifest_.tolerance * (1 + 1e-9);
  if (!parameter_ok)
    throw FormatError(
        path, offsetof(FrameHeader, codec_parameter),
        manifest_.codec == Codec::zfp
            ? "zfp accuracy " + number_text(manifest_.zfp_accuracy) + " (manifest.json)"
        : manifest_.fixed_sparsity > 0
            ? std::string("0 (fixed rate)")
            : "a tolerance in (0, " + number_text(manifest_.tolerance) + "] (manifest.json)",
        number_text(parameter));
  // The first and last steps store every node; so does every step without keyframe gaps.
  if (h.brick_count != h.node_count &&
      (t == 0 || t + 1 == manifest_.frames.size() || manifest_.max_keyframe_gap == 1))
    throw FormatError(path, offsetof(FrameHeader, brick_count),
                      "a brick for each of the " + std::to_string(h.node_count) + " nodes (" +
                          (manifest_.max_keyframe_gap == 1
                               ? std::string("max_keyframe_gap 1: every step stores every node")
                               : std::string("the first and last steps store every node")) +
                          ")",
                      std::to_string(h.brick_count) + " bricks");
  if (manifest_.codec == Codec::ksvd && h.atom_count != atom_count_)
    throw FormatError(path, offsetof(FrameHeader, atom_count),
                      std::to_string(atom_count_) + " atoms (the dictionary's)",
                      std::to_string(h.atom_count));
}

std::uint64_t Container::total_bytes() const {
  std::uint64_t total = manifest_bytes_;
  if (manifest_.dictionary) total += manifest_.dictionary->bytes;
  for (const auto& f : manifest_.frames)
    if (f) total += f->bytes;
  return total;
}

namespace {

std::uint64_t dilate_bins(std::uint64_t bins, std::uint32_t k) {
  std::uint64_t out = bins;
  for (std::uint32_t i = 1; i <= k && i < 64; ++i) out |= (bins << i) | (bins >> i);
  return out;
}

/// Decodes every brick of the frame (throwing on the first bad one), and checks the finest
/// level's histograms against the decoded bricks: every decoded value's bin near a bin
/// of the node's histogram, and every bin of the histogram near a decoded value, "near" being the
/// bins the codec's error can move a value across (the histogram counts the original voxels).
/// A histogram that leaves out values would hide them from the renderer's culling; one with bins
/// no value comes near is not this brick's. Fixed rate has no error bound: not checked.
void decode_and_check_histograms(const FrameView& view, const AtomTable& atoms) {
  const FrameHeader& h = view.header();
  const double range = static_cast<double>(h.value_max) - static_cast<double>(h.value_min);
  // zfp's accuracy bounds every error; a ksvd ε bounds a block's RMS error, a value's error is
  // taken as at most 50 ε.
  const double error = view.codec() == Codec::zfp ? 2 * h.codec_parameter : 50 * h.codec_parameter;
  const bool check = range > 0 && error > 0;
  const auto k = check ? static_cast<std::uint32_t>(
                             std::min(64.0, std::ceil(error / (range / histogram_bins)) + 1))
                       : 0u;
  const std::uint32_t finest = view.level(view.level_count() - 1).first_node;
  std::vector<float> brick(view.shape().voxels());
  // Every brick decoded once (what validate_payloads does); the finest level's non-constant
  // bricks also against their histograms (constant ones are checked by the reader). A node
  // without a brick at this step has the histogram of the frame's data, which its interpolated
  // values need not match.
  const std::uint32_t side = view.shape().size;
  for (std::uint32_t i = 0; i < view.node_count(); ++i) {
    const Node n = view.node(i);
    if (n.brick == no_brick) continue;
    decode_brick(view, n.brick, atoms, brick);
    // A ksvd brick codes the blocks its position in the level needs (the box word); the voxels
    // past them decode to a placeholder no renderer reads, left out of the histogram check.
    std::uint32_t end[3] = {side, side, side};
    const auto payload = view.brick_bytes(n.brick);
    if (view.codec() == Codec::ksvd && payload.size() != 4) {
      const NodePosition p = view.position(i);
      const LevelEntry& level = view.level(p.level);
      const auto box =
          coded_box(view.shape(), {p.x, p.y, p.z}, {level.dims[0], level.dims[1], level.dims[2]});
      const std::uint32_t word = ksvd_box_word(payload);  // checked by the decode above
      for (std::size_t a = 0; a < 3; ++a) {
        const vr_uint coded = vr_box_blocks(word, static_cast<vr_uint>(a));
        if (coded < box[a])
          throw FormatError(view.name(), view.brick_offset(n.brick) + 4 * 5,
                            "node " + std::to_string(i) + " box word with at least " +
                                std::to_string(box[0]) + " x " + std::to_string(box[1]) + " x " +
                                std::to_string(box[2]) + " coded blocks (its position's)",
                            std::to_string(vr_box_blocks(word, 0)) + " x " +
                                std::to_string(vr_box_blocks(word, 1)) + " x " +
                                std::to_string(vr_box_blocks(word, 2)));
        end[a] = coded * VR_BLOCK_SIZE;
      }
    }
    if (!check || i < finest || payload.size() == 4) continue;
    std::uint64_t decoded = 0;
    for (std::uint32_t z = 0; z < end[2]; ++z)
      for (std::uint32_t y = 0; y < end[1]; ++y)
        for (std::uint32_t x = 0; x < end[0]; ++x)
          decoded |= std::uint64_t{1} << histogram_bin(
                         brick[(std::size_t{z} * side + y) * side + x], h.value_min, h.value_max);
    const std::uint64_t at = h.node_table_offset + sizeof(Node) * std::uint64_t{i} + 8;
    if ((decoded & ~dilate_bins(n.histogram, k)) != 0)
      throw FormatError(view.name(), at,
                        "node " + std::to_string(i) + " histogram with the bins of its decoded " +
                            "values (within " + std::to_string(k) + " bins)",
                        "a histogram that leaves some of them out");
    if ((n.histogram & ~dilate_bins(decoded, k)) != 0)
      throw FormatError(view.name(), at,
                        "node " + std::to_string(i) + " histogram of bins its decoded values " +
                            "come within " + std::to_string(k) + " bins of",
                        "bins no value comes near");
  }
}

}  // namespace

std::vector<std::string> verify_container(const fs::path& dir,
                                          void (*progress)(std::size_t, std::size_t, void*),
                                          void* user) {
  std::shared_ptr<const ContainerSource> source;
  try {
    source = std::make_shared<LocalSource>(dir);
  } catch (const FormatError& e) {
    return {e.what()};
  }
  return verify_container(std::move(source), progress, user);
}

std::vector<std::string> verify_container(std::shared_ptr<const ContainerSource> source,
                                          void (*progress)(std::size_t, std::size_t, void*),
                                          void* user) {
  std::vector<std::string> problems;
  std::optional<Container> container;
  try {
    container.emplace(source, true);
  } catch (const FormatError& e) {
    problems.push_back(e.what());
    return problems;
  }
  const Manifest& m = container->manifest();
  if (!m.complete)
    problems.push_back(source->name("manifest.json").string() + ": the encode is not complete");
  // The container identifier is the hash of the settings and the dictionary (SPEC.md): a setting
  // edited after encoding, with the manifest's checksum made again, changes it.
  std::optional<std::vector<std::byte>> dictionary_without_id;
  if (!m.dictionary) dictionary_without_id.emplace();
  if (m.dictionary) {
    const fs::path p = source->name(m.dictionary->file);
    try {
      const auto bytes = source->read_file(m.dictionary->file, detail::max_dictionary_bytes);
      if (bytes.size() != m.dictionary->bytes)
        problems.push_back(p.string() + ": expected " + std::to_string(m.dictionary->bytes) +
                           " bytes (manifest.json), found " + std::to_string(bytes.size()));
      else if (manifest_crc(bytes) != m.dictionary->crc32c)
        problems.push_back(p.string() + ": expected CRC-32C " +
                           std::to_string(m.dictionary->crc32c) + " (manifest.json), found " +
                           std::to_string(manifest_crc(bytes)));
      DictionaryFile file = parse_dictionary_file(bytes, p);
      file.container_id = 0;
      dictionary_without_id = serialize_dictionary_file(file);
    } catch (const FormatError& e) {
      problems.push_back(e.what());
    }
  }
  if (dictionary_without_id) {
    Manifest settings = m;
    settings.dictionary.reset();
    const std::uint64_t id = container_identifier(settings, *dictionary_without_id);
    if (id != m.container_id &&
        container_identifier(settings, *dictionary_without_id, true) != m.container_id)
      problems.push_back(source->name("manifest.json").string() + ": expected \"container_id\" " +
                         id_text(id) + " (the hash of the settings and the dictionary), found " +
                         id_text(m.container_id) + ": a setting changed after encoding");
  }
  // Files in frames/ that the manifest does not list: left by an encode of more frames, or by an
  // interrupted one (a temporary file; encode --resume removes it).
  if (const auto dir = source->local_directory()) {
    std::unordered_set<std::string> listed;  // written frames' files, and the names of the rest
    for (std::size_t t = 0; t < m.frames.size(); ++t)
      listed.insert(m.frames[t] ? m.frames[t]->file : frame_file_name(t));
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator(*dir / "frames", ec)) {
      const std::string name = entry.path().filename().string();
      if (!listed.contains("frames/" + name))
        problems.push_back(entry.path().string() +
                           (name.find(".tmp-") != std::string::npos
                                ? ": a temporary file an interrupted encode left (encode --resume "
                                  "removes it)"
                                : ": a file the manifest does not list (frame_count " +
                                      std::to_string(m.frames.size()) + ")"));
    }
  }
  TimeStepDecoder steps(*container);
  for (std::size_t t = 0; t < m.frames.size(); ++t) {
    try {
      // The frame as the decoder holds it (opened once: over HTTP, read once).
      steps.check_keyframes(t);
      const FrameView& f = steps.frame(t);
      f.check_payload_crc();
      const std::uint32_t crc = manifest_crc(f.bytes());
      if (crc != m.frames[t]->crc32c)
        problems.push_back(f.name().string() + ": expected CRC-32C " +
                           std::to_string(m.frames[t]->crc32c) + " (manifest.json), found " +
                           std::to_string(crc));
      decode_and_check_histograms(f, container->atoms());
    } catch (const FormatError& e) {
      // A frame that other steps' keyframes come from fails each of their checks alike: once.
      if (std::find(problems.begin(), problems.end(), e.what()) == problems.end())
        problems.push_back(e.what());
    }
    if (progress) progress(t + 1, m.frames.size(), user);
  }
  return problems;
}

}  // namespace volreel::format
