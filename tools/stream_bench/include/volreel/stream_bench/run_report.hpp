// run_report.hpp: a `volreel bench stream` run written out — one CSV row per rendered frame, the
// run's summary as JSON (summary.json's "runs" entries), and the table that prints runs side by
// side.
#pragma once

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "volreel/stream_bench/run_summary.hpp"

namespace volreel::stream_bench {

/// "1.23 MB" (10^6 bytes, two decimals).
std::string mb_text(double bytes);
/// "1.23 s", or "-" for NaN (not reached).
std::string seconds_or_dash(double seconds);

/// One row per frame of `run` (`seeks`: (tour time, keyframe) pairs; a frame at or after a seek
/// not yet passed is marked 1 in the seek column). Throws InputError naming the file when it
/// cannot be written.
void write_csv(const std::filesystem::path& path, const RunResult& run,
               const std::vector<std::pair<double, double>>& seeks);
/// The run's averages and seeks; NaN and infinite values as null.
nlohmann::json summary_json(const RunResult& run);
/// The runs' averages and seek times side by side on stdout, one column per run.
void print_side_by_side(const std::vector<RunResult>& runs);

}  // namespace volreel::stream_bench
