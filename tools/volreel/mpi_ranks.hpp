// mpi_ranks.hpp: the encoder's Ranks over MPI_COMM_WORLD, when volreel is built with MPI and
// started by mpirun (or another MPI launcher). Without a launcher volreel never initialises MPI,
// so a plain `volreel encode` runs exactly as a build without MPI.
#pragma once

#include <memory>

#include "volreel/encoder/ranks.hpp"

namespace volreel::cli {

/// Initialises MPI when the environment says a launcher started this process; finalises it when
/// it goes.
class MpiSession {
 public:
  MpiSession(int& argc, char**& argv);
  ~MpiSession();
  MpiSession(const MpiSession&) = delete;
  MpiSession& operator=(const MpiSession&) = delete;
  /// Ends every process of the job after an error on this one (MPI_Abort), so that none waits
  /// for it; does nothing outside MPI or with a single process.
  static void abort_job(int code);
};

/// The ranks of MPI_COMM_WORLD when MPI is running with more than one process, else null.
const encoder::Ranks* mpi_ranks();

}  // namespace volreel::cli
