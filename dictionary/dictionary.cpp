// dictionary.cpp: atom normalization and conversion to and from the dictionary file.
#include "volreel/dictionary/dictionary.hpp"

#include <cstring>

namespace volreel::dictionary {

void normalize_atoms(Eigen::MatrixXf& atoms) {
  const auto m = atoms.rows();
  for (Eigen::Index k = 0; k < atoms.cols(); ++k) {
    auto atom = atoms.col(k);
    atom.array() -= atom.mean();
    float norm = atom.norm();
    if (!(norm > 1e-20f)) {
      atom.setConstant(-1.0f / static_cast<float>(m));
      atom(0) += 1.0f;
      norm = atom.norm();
    }
    atom /= norm;
  }
}

format::DictionaryFile to_file(const Dictionary& dictionary,
                               const format::DictionaryTraining& training) {
  format::DictionaryFile file;
  file.block_size = static_cast<std::uint32_t>(dictionary.block_size);
  file.atom_count = static_cast<std::uint32_t>(dictionary.atom_count());
  file.atoms.assign(dictionary.atoms.data(), dictionary.atoms.data() + dictionary.atoms.size());
  file.training = training;
  file.program_version = VOLREEL_VERSION;
  return file;
}

Dictionary from_file(const format::DictionaryFile& file) {
  Dictionary dictionary;
  dictionary.block_size = static_cast<int>(file.block_size);
  const auto m = static_cast<Eigen::Index>(file.block_size) * file.block_size * file.block_size;
  dictionary.atoms = Eigen::Map<const Eigen::MatrixXf>(file.atoms.data(), m,
                                                       static_cast<Eigen::Index>(file.atom_count));
  return dictionary;
}

void save_dictionary(const std::filesystem::path& path, const Dictionary& dictionary,
                     const format::DictionaryTraining& training) {
  format::write_dictionary_file(path, to_file(dictionary, training));
}

Dictionary load_dictionary(const std::filesystem::path& path) {
  return from_file(format::read_dictionary_file(path));
}

}  // namespace volreel::dictionary
