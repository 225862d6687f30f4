// default_dictionary.hpp: the dictionary an encode trains when it is given none — Algorithm 1
// (dictionary/training.hpp) with the library's default options at the ε of the encode, and, since
// the dictionary counts in the container's size, K chosen by the container size it gives.
#pragma once

#include <cstddef>
#include <functional>
#include <vector>

#include "volreel/datasets/series.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/dictionary/coreset.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/encoder/coding_settings.hpp"
#include "volreel/format/dictionary_file.hpp"

namespace volreel::encoder {

struct DefaultDictionaryOptions {
  double tolerance = 0;  ///< ε to train at and (choosing K) to code the sample frames at, > 0
  /// K of the dictionary; 0: train one for each of candidate_atoms that can still win and keep
  /// the K whose estimated container (sample frames' mean size × frames + dictionary file) is the
  /// smallest.
  int atoms = 0;
  /// 0: the DCT basis alone (nothing trained; the file is the 132-byte header and CRC), which wins
  /// on series too small to pay for learned atoms. Tried in this order: the DCT basis first, then
  /// the learned sizes from the smallest; a K whose dictionary file alone is at least the smallest
  /// container estimated before it cannot win, and is not trained; nor is any K after
  /// max_rising_estimates candidates in a row whose estimate rose (past the minimum of a curve
  /// that falls while more atoms save more than they cost and rises after).
  std::vector<int> candidate_atoms = {0, 128, 256, 512, 1024};
  std::size_t frames = 0;         ///< frames the container will hold (0: all of the series)
  std::size_t sample_frames = 3;  ///< choosing K: frames coded with each dictionary, evenly spaced
  /// The container stores the atoms in binary16: dictionary sizes and sample frames count them so.
  bool half_atoms = true;
  /// How the sample frames are coded (value range set); variable rate at `tolerance` whatever its
  /// tolerance and fixed_sparsity say.
  CodingSettings coding;
  /// The coreset hierarchy trained on. Training takes dictionary::TrainingOptions' defaults
  /// (volreel train's, except that every level runs its N iterations: no convergence test).
  dictionary::CoresetOptions coreset;
};

/// One K tried, reported as soon as its dictionary is trained (and, choosing K, measured) or
/// skipped.
struct DictionaryCandidate {
  int atoms = 0;                ///< K
  double train_seconds = 0;     ///< training time (the coreset is built once, before)
  double dictionary_bytes = 0;  ///< its file, the atoms stored as the container stores them
  double estimated_bytes = 0;   ///< choosing K: the estimated container; 0 when K was given
  /// Choosing K: not trained (estimated_bytes and train_seconds are then 0), its dictionary_bytes
  /// being at least best_bytes, the smallest container estimated before it; or, `past_minimum`,
  /// after max_rising_estimates candidates in a row whose estimate rose.
  bool skipped = false;
  bool past_minimum = false;
  double best_bytes = 0;
};
/// See DefaultDictionaryOptions::candidate_atoms. Two rises in a row rather than one, so that a
/// size that happens to code the sample frames a little worse does not end the search.
inline constexpr int max_rising_estimates = 2;
using DictionaryCandidateCallback = std::function<void(const DictionaryCandidate&)>;

struct DefaultDictionary {
  /// The DCT basis alone won (candidate K = 0): `dictionary` and `training` are empty, and the
  /// dictionary file to use is format::dct_dictionary.
  bool dct_only = false;
  dictionary::Dictionary dictionary;    ///< the chosen one, float32 atoms as trained
  format::DictionaryTraining training;  ///< its provenance (dictionary::training_provenance)
  std::vector<DictionaryCandidate> candidates;  ///< every K, in the order tried, skipped ones too
};

/// Trains a dictionary on `coresets` (built from `series` with options.coreset) at
/// options.tolerance for options.atoms or each candidate K that can still win (a K whose
/// dictionary alone is at least the smallest estimate so far is skipped, and every K after
/// max_rising_estimates rising estimates in a row), reporting each K, trained
/// or skipped, to on_candidate, and
/// returns the one chosen. Throws InputError when K is to be chosen without a candidate or a
/// sample frame, and where training and the frame encoder do.
DefaultDictionary train_default_dictionary(const datasets::SeriesReader& series,
                                           const dictionary::CoresetHierarchy& coresets,
                                           const DefaultDictionaryOptions& options,
                                           const DictionaryCandidateCallback& on_candidate = {});
/// The same, building the coreset hierarchy first (reporting to coreset_progress).
DefaultDictionary train_default_dictionary(const datasets::SeriesReader& series,
                                           const DefaultDictionaryOptions& options,
                                           const Progress& coreset_progress = {},
                                           const DictionaryCandidateCallback& on_candidate = {});

}  // namespace volreel::encoder
