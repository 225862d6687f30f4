// mpi_ranks.cpp: encoder::Ranks over MPI_COMM_WORLD (mpi_ranks.hpp).
#include "mpi_ranks.hpp"

#include "volreel/datasets/volume.hpp"

#include <cstdlib>
#include <limits>
#include <stdexcept>
#include <string>

#ifdef VOLREEL_HAVE_MPI
#include <mpi.h>
#endif

namespace volreel::cli {

#ifdef VOLREEL_HAVE_MPI

namespace {

bool started_by_launcher() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE"})
    if (std::getenv(name)) return true;
  return false;
}

void check(int code, const char* call) {
  if (code == MPI_SUCCESS) return;
  char text[MPI_MAX_ERROR_STRING];
  int length = 0;
  MPI_Error_string(code, text, &length);
  throw std::runtime_error(std::string(call) +
                           " failed: " + std::string(text, static_cast<std::size_t>(length)));
}

int to_count(std::size_t n) {
  if (n > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw std::runtime_error("an MPI message of " + std::to_string(n) +
                             " elements is larger than MPI's int counts allow");
  return static_cast<int>(n);
}

/// The processes of one communicator: MPI_COMM_WORLD, which holds the job's progress count, or a
/// team split from it (`job`: the world's ranks, where its progress goes).
class CommRanks final : public encoder::Ranks {
 public:
  CommRanks() : comm_(MPI_COMM_WORLD) {
    MPI_Comm_rank(comm_, &rank_);
    MPI_Comm_size(comm_, &size_);
    // The job's progress count: one double in rank 0's window, which every rank adds to.
    double* count = nullptr;
    check(MPI_Win_allocate(rank_ == 0 ? sizeof(double) : 0, sizeof(double), MPI_INFO_NULL, comm_,
                           &count, &progress_),
          "MPI_Win_allocate");
    if (rank_ == 0) *count = 0;
    check(MPI_Barrier(comm_), "MPI_Barrier");
  }
  CommRanks(MPI_Comm team, const CommRanks* job) : comm_(team), job_(job) {
    MPI_Comm_rank(comm_, &rank_);
    MPI_Comm_size(comm_, &size_);
  }
  ~CommRanks() override {
    if (progress_ != MPI_WIN_NULL) MPI_Win_free(&progress_);
    if (comm_ != MPI_COMM_WORLD) MPI_Comm_free(&comm_);
  }
  CommRanks(const CommRanks&) = delete;
  CommRanks& operator=(const CommRanks&) = delete;
  int rank() const override { return rank_; }
  int size() const override { return size_; }
  void sum(std::span<double> v) const override { reduce(v, MPI_SUM); }
  void min(std::span<double> v) const override { reduce(v, MPI_MIN); }
  void max(std::span<double> v) const override { reduce(v, MPI_MAX); }
  void broadcast(std::vector<std::byte>& bytes) const override {
    unsigned long long n = bytes.size();
    check(MPI_Bcast(&n, 1, MPI_UNSIGNED_LONG_LONG, 0, comm_), "MPI_Bcast");
    bytes.resize(static_cast<std::size_t>(n));
    check(MPI_Bcast(bytes.data(), to_count(bytes.size()), MPI_BYTE, 0, comm_), "MPI_Bcast");
  }
  std::vector<std::uint64_t> gather(std::span<const std::uint64_t> values) const override {
    const int mine = to_count(values.size());
    std::vector<int> counts(static_cast<std::size_t>(size_)), offsets(counts.size());
    check(MPI_Allgather(&mine, 1, MPI_INT, counts.data(), 1, MPI_INT, comm_), "MPI_Allgather");
    std::size_t total = 0;
    for (std::size_t r = 0; r < counts.size(); ++r) {
      offsets[r] = to_count(total);
      total += static_cast<std::size_t>(counts[r]);
    }
    std::vector<std::uint64_t> all(total);
    static_assert(sizeof(unsigned long long) == sizeof(std::uint64_t));
    check(MPI_Allgatherv(values.data(), mine, MPI_UNSIGNED_LONG_LONG, all.data(), counts.data(),
                         offsets.data(), MPI_UNSIGNED_LONG_LONG, comm_),
          "MPI_Allgatherv");
    return all;
  }
  std::vector<std::vector<std::byte>> gather_to_root(
      std::span<const std::byte> bytes) const override {
    const unsigned long long mine = bytes.size();
    std::vector<unsigned long long> sizes(static_cast<std::size_t>(size_));
    check(MPI_Gather(&mine, 1, MPI_UNSIGNED_LONG_LONG, sizes.data(), 1, MPI_UNSIGNED_LONG_LONG, 0,
                     comm_),
          "MPI_Gather");
    std::vector<int> counts(sizes.size()), offsets(sizes.size());
    std::size_t total = 0;
    for (std::size_t r = 0; r < sizes.size() && rank_ == 0; ++r) {
      counts[r] = to_count(static_cast<std::size_t>(sizes[r]));
      offsets[r] = to_count(total);
      total += static_cast<std::size_t>(sizes[r]);
    }
    std::vector<std::byte> all(total);
    check(MPI_Gatherv(bytes.data(), to_count(bytes.size()), MPI_BYTE, all.data(), counts.data(),
                      offsets.data(), MPI_BYTE, 0, comm_),
          "MPI_Gatherv");
    std::vector<std::vector<std::byte>> parts;
    for (std::size_t r = 0; r < sizes.size() && rank_ == 0; ++r) {
      const auto* first = all.data() + offsets[r];
      parts.emplace_back(first, first + counts[r]);
    }
    return parts;
  }
  void barrier() const override { check(MPI_Barrier(comm_), "MPI_Barrier"); }
  void add_progress(double amount) const override {
    if (job_) return job_->add_progress(amount);
    check(MPI_Win_lock(MPI_LOCK_SHARED, 0, 0, progress_), "MPI_Win_lock");
    check(MPI_Accumulate(&amount, 1, MPI_DOUBLE, 0, 0, 1, MPI_DOUBLE, MPI_SUM, progress_),
          "MPI_Accumulate");
    check(MPI_Win_unlock(0, progress_), "MPI_Win_unlock");
  }
  double progress_count() const override {
    if (job_) return job_->progress_count();
    double none = 0, value = 0;
    check(MPI_Win_lock(MPI_LOCK_SHARED, 0, 0, progress_), "MPI_Win_lock");
    check(MPI_Fetch_and_op(&none, &value, MPI_DOUBLE, 0, 0, MPI_NO_OP, progress_),
          "MPI_Fetch_and_op");
    check(MPI_Win_unlock(0, progress_), "MPI_Win_unlock");
    return value;
  }
  std::unique_ptr<encoder::Ranks> split(int color) const override {
    MPI_Comm team = MPI_COMM_NULL;
    check(MPI_Comm_split(comm_, color, rank_, &team), "MPI_Comm_split");
    return std::make_unique<CommRanks>(team, job_ ? job_ : this);
  }

 private:
  void reduce(std::span<double> v, MPI_Op op) const {
    check(MPI_Allreduce(MPI_IN_PLACE, v.data(), to_count(v.size()), MPI_DOUBLE, op, comm_),
          "MPI_Allreduce");
  }
  MPI_Comm comm_;
  const CommRanks* job_ = nullptr;
  int rank_ = 0, size_ = 1;
  MPI_Win progress_ = MPI_WIN_NULL;
};

bool initialised_here = false;
std::unique_ptr<CommRanks> world;

}  // namespace

MpiSession::MpiSession(int& argc, char**& argv) {
  if (!started_by_launcher()) return;
  // Only the main thread calls MPI (OpenMP threads never do).
  int provided = 0;
  if (MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS) return;
  initialised_here = true;
  // Errors come back as codes (check() turns them into exceptions) rather than ending the job.
  MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
  world = std::make_unique<CommRanks>();
}

MpiSession::~MpiSession() {
  world.reset();
  if (initialised_here) MPI_Finalize();
}

void MpiSession::abort_job(int code) {
  if (initialised_here && world && world->size() > 1) MPI_Abort(MPI_COMM_WORLD, code);
}

const encoder::Ranks* mpi_ranks() {
  return world && world->size() > 1 ? world.get() : nullptr;
}

#else

namespace {

/// Started as one of several processes by an MPI launcher.
bool launched_as_several() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE"})
    if (const char* v = std::getenv(name); v && std::atoi(v) > 1) return true;
  return false;
}

}  // namespace

MpiSession::MpiSession(int&, char**&) {}
MpiSession::~MpiSession() = default;
void MpiSession::abort_job(int) {}
const encoder::Ranks* mpi_ranks() {
  // Each process would encode the whole series into the same folder.
  if (launched_as_several())
    throw InputError(
        "this volreel was built without MPI, so several processes started by mpirun cannot share "
        "an encode: install libopenmpi-dev (scripts/install-deps) and build again, or run one "
        "process");
  return nullptr;
}

#endif

}  // namespace volreel::cli
