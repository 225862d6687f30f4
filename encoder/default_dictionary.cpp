// default_dictionary.cpp: training the dictionary of an encode that is given none, and choosing
// its K by trial encodes of sample frames.
#include "volreel/encoder/default_dictionary.hpp"

#include <algorithm>
#include <limits>

#include "detail.hpp"
#include "volreel/dictionary/training.hpp"
#include "volreel/encoder/frame_encoder.hpp"

namespace volreel::encoder {

DefaultDictionary train_default_dictionary(const datasets::SeriesReader& series,
                                           const dictionary::CoresetHierarchy& h,
                                           const DefaultDictionaryOptions& options,
                                           const DictionaryCandidateCallback& on_candidate) {
  const bool choose = options.atoms == 0;
  const std::size_t frames = options.frames ? options.frames : series.info().frames;
  if (choose && options.candidate_atoms.empty())
    throw InputError("no dictionary size to try: give --atoms");
  if (choose && std::min(options.sample_frames, frames) == 0)
    throw InputError(
        "choosing the dictionary size needs at least one sample frame (--rate-sample-frames)");
  // 1. The sample frames, in memory.
  std::vector<Volume> samples;
  if (choose) samples = detail::evenly_spaced_frames(series, frames, options.sample_frames);
  // 2. Each K: train, unless (choosing) its dictionary alone cannot win; choosing, code the
  //    samples against the atoms as the container stores them.
  DefaultDictionary result;
  double best_total = std::numeric_limits<double>::infinity();
  double previous_total = std::numeric_limits<double>::infinity();  // the last one trained
  int rises = 0;  // candidates in a row whose estimate was larger than the one before
  for (int k : choose ? options.candidate_atoms : std::vector<int>{options.atoms}) {
    dictionary::TrainingOptions to;
    to.atom_count = k;
    to.coding.tolerance = options.tolerance;
    DictionaryCandidate candidate;
    candidate.atoms = k;
    candidate.dictionary_bytes = static_cast<double>(
        format::dictionary_file_size(static_cast<std::uint64_t>(k), 216, options.half_atoms));
    const bool past_minimum = rises >= max_rising_estimates;
    if (choose && (candidate.dictionary_bytes >= best_total || past_minimum)) {  // not trained
      candidate.skipped = true;
      candidate.past_minimum = candidate.dictionary_bytes < best_total;  // the other reason
      candidate.best_bytes = best_total;
      result.candidates.push_back(candidate);
      if (on_candidate) on_candidate(candidate);
      continue;
    }
    const auto start = detail::Clock::now();
    dictionary::TrainingResult r;
    if (k > 0) r = dictionary::train_dictionary(h, to);  // K = 0: the DCT basis alone
    candidate.train_seconds = detail::seconds_since(start);
    const auto stored = dictionary::from_file(
        k > 0 ? format::container_dictionary(
                    dictionary::to_file(r.dictionary, format::DictionaryTraining{}),
                    options.half_atoms)
              : format::dct_dictionary(6, ""));
    double total = candidate.dictionary_bytes;
    if (choose) {
      auto c = options.coding;
      c.tolerance = options.tolerance;
      c.fixed_sparsity = 0;
      const FrameEncoder enc(&stored, c);
      double bytes = 0;
      for (std::size_t i = 0; i < samples.size(); ++i)
        bytes += static_cast<double>(enc.encode(i, samples[i]).size());
      total += bytes / static_cast<double>(samples.size()) * static_cast<double>(frames);
      candidate.estimated_bytes = total;
      rises = total > previous_total ? rises + 1 : 0;
      previous_total = total;
    }
    result.candidates.push_back(candidate);
    if (on_candidate) on_candidate(candidate);
    // 3. The smallest estimated container wins (the first of equals).
    if (total < best_total) {
      best_total = total;
      result.dct_only = k == 0;
      result.training = k > 0 ? dictionary::training_provenance(options.coreset, to, h, r)
                              : format::DictionaryTraining{};
      result.dictionary = std::move(r.dictionary);
    }
  }
  return result;
}

DefaultDictionary train_default_dictionary(const datasets::SeriesReader& series,
                                           const DefaultDictionaryOptions& options,
                                           const Progress& coreset_progress,
                                           const DictionaryCandidateCallback& on_candidate) {
  const dictionary::CoresetHierarchy h =
      dictionary::build_coreset_hierarchy(series, options.coreset, coreset_progress);
  return train_default_dictionary(series, h, options, on_candidate);
}

}  // namespace volreel::encoder
