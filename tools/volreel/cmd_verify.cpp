// cmd_verify.cpp: `volreel verify` — check every CRC and the structure of a NAME.vreel container
// and decode every brick (format::verify_container), naming each problem found.
#include <cstdio>
#include <memory>
#include <string>

#include "commands.hpp"
#include "progress.hpp"
#include "remote_options.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/error.hpp"

namespace volreel::cli {

namespace {

void run_verify(const std::string& location, const RemoteCli& remote) {
  const std::string dir = remote::without_credentials(location);  // as messages show it
  std::shared_ptr<const format::ContainerSource> source;
  try {
    source = open_container_source(location, remote);
  } catch (const format::FormatError& e) {
    throw InputError(std::string(e.what()) + " (1 problem found)");
  }
  ProgressBar bar("verifying", "frames");
  const auto problems = format::verify_container(
      source,
      [](std::size_t done, std::size_t total, void* user) {
        static_cast<ProgressBar*>(user)->update(
            {static_cast<double>(done), static_cast<double>(total), {}});
      },
      &bar);
  bar.finish();
  print_remote_summary(*source, "verify");
  for (const auto& p : problems) std::fprintf(stderr, "%s\n", p.c_str());
  if (problems.size() == 1) throw InputError(dir + ": 1 problem found: " + problems.front());
  if (!problems.empty())
    throw InputError(dir + ": " + std::to_string(problems.size()) +
                     " problems found, the first: " + problems.front() + " (the rest above)");
  std::printf("%s: OK (manifest, dictionary, every frame's CRC-32C, index and brick payloads)\n",
              dir.c_str());
}

}  // namespace

void add_verify_command(CLI::App& app) {
  auto verify_dir = std::make_shared<std::string>();
  auto remote = std::make_shared<RemoteCli>();
  CLI::App* verify = app.add_subcommand(
      "verify", "Check every CRC and structure of a NAME.vreel container, and decode every brick");
  verify->add_option("CONTAINER", *verify_dir, container_argument_help)->required();
  add_remote_options(*verify, *remote);
  verify->callback([verify_dir, remote] { run_verify(*verify_dir, *remote); });
}

}  // namespace volreel::cli
