// ranks.hpp: the processes that encode one container together — MPI ranks when volreel runs
// under mpirun, one process otherwise. The encoder sees only this interface, so it builds and
// runs without MPI; the MPI implementation lives with the program (tools/volreel/mpi_ranks.hpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <utility>
#include <vector>

namespace volreel::encoder {

/// Collective operations over the processes of one encode. Every process must call each of them
/// in the same order (MPI's rule); a single process's calls return their input.
class Ranks {
 public:
  virtual ~Ranks() = default;
  virtual int rank() const = 0;
  virtual int size() const = 0;
  /// Element-wise sum, minimum and maximum across the processes, in place, on every process.
  virtual void sum(std::span<double> values) const = 0;
  virtual void min(std::span<double> values) const = 0;
  virtual void max(std::span<double> values) const = 0;
  /// Rank 0's bytes to every process (resized there).
  virtual void broadcast(std::vector<std::byte>& bytes) const = 0;
  /// Every process's values, concatenated in rank order, on every process.
  virtual std::vector<std::uint64_t> gather(std::span<const std::uint64_t> values) const = 0;
  /// Every process's bytes, in rank order, on rank 0 (an empty list elsewhere).
  virtual std::vector<std::vector<std::byte>> gather_to_root(
      std::span<const std::byte> bytes) const = 0;
  /// Returns when every process has called it.
  virtual void barrier() const = 0;
  /// A job-wide count (frames coded, for one progress bar): each process adds what it did;
  /// progress_count() is the sum of what every process added so far. Neither waits for the
  /// other processes (one-sided), so they need not be called in the same order everywhere.
  /// A single process keeps no count (it reports its own work).
  virtual void add_progress(double amount) const = 0;
  virtual double progress_count() const = 0;
  /// The processes that called it with the same `color` (collective over every process), ranked
  /// as here. A team keeps no progress count: add_progress and progress_count go to the job's.
  virtual std::unique_ptr<Ranks> split(int color) const = 0;

  bool root() const { return rank() == 0; }
  /// The part [first, last) of n items (frames, stretches) that this process takes: contiguous,
  /// sizes differing by at most one.
  std::pair<std::size_t, std::size_t> share(std::size_t n) const;
  /// Part `part` of `parts` of n items: [n·part/parts, n·(part+1)/parts).
  static std::pair<std::size_t, std::size_t> share_of(std::size_t n, std::size_t part,
                                                      std::size_t parts);
  /// A double from rank 0 to every process.
  double broadcast_value(double value) const;
};

/// One process alone.
class SingleProcess final : public Ranks {
 public:
  int rank() const override { return 0; }
  int size() const override { return 1; }
  void sum(std::span<double>) const override {}
  void min(std::span<double>) const override {}
  void max(std::span<double>) const override {}
  void broadcast(std::vector<std::byte>&) const override {}
  std::vector<std::uint64_t> gather(std::span<const std::uint64_t> values) const override {
    return {values.begin(), values.end()};
  }
  std::vector<std::vector<std::byte>> gather_to_root(
      std::span<const std::byte> bytes) const override {
    return {{bytes.begin(), bytes.end()}};
  }
  void barrier() const override {}
  void add_progress(double) const override {}
  double progress_count() const override { return 0; }
  std::unique_ptr<Ranks> split(int) const override { return std::make_unique<SingleProcess>(); }
};

/// The SingleProcess every encode uses unless given other Ranks.
const Ranks& single_process();

}  // namespace volreel::encoder
