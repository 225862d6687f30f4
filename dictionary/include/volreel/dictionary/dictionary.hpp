// dictionary.hpp: a learned dictionary of prototype blocks in memory, and its file.
#pragma once

#include <filesystem>

#include <Eigen/Core>

#include "volreel/format/dictionary_file.hpp"

namespace volreel::dictionary {

/// K atoms of m = M³ values, one per column; every atom zero-mean with unit L2 norm.
struct Dictionary {
  int block_size = 6;
  Eigen::MatrixXf atoms;  ///< m × K

  int block_length() const { return static_cast<int>(atoms.rows()); }
  int atom_count() const { return static_cast<int>(atoms.cols()); }
};

/// Subtracts each column's mean and scales it to unit norm; a column that is (numerically) zero
/// becomes e0 − mean, normalized, so that no atom is ever the zero vector.
void normalize_atoms(Eigen::MatrixXf& atoms);

/// Dictionary -> file contents, with the training parameters as provenance.
format::DictionaryFile to_file(const Dictionary& dictionary,
                               const format::DictionaryTraining& training);
/// File contents -> dictionary (atoms are used as stored).
Dictionary from_file(const format::DictionaryFile& file);

/// Writes PATH atomically; throws format::FormatError on failure.
void save_dictionary(const std::filesystem::path& path, const Dictionary& dictionary,
                     const format::DictionaryTraining& training);
/// Reads PATH; throws format::FormatError naming the file, offset and problem if it is bad.
Dictionary load_dictionary(const std::filesystem::path& path);

}  // namespace volreel::dictionary
