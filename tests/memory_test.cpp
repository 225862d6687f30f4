// memory_test.cpp: format::detail::usable_memory_bytes — the machine's memory, lowered by a
// cgroup's limit (v2 memory.max, v1 memory.limit_in_bytes), never raised by one and never by a
// file that says "max" or holds no number.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include "test_util.hpp"
#include "volreel/format/memory.hpp"

namespace volreel {
namespace {

namespace fs = std::filesystem;

void put(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream(path) << text;
}

TEST(UsableMemory, TheLowerOfTheMachineAndItsControlGroupsLimit) {
  test::TempDir dir("usable-memory");
  const fs::path none = dir / "none";
  const std::uint64_t machine = format::detail::usable_memory_bytes(none, none);
  ASSERT_GT(machine, std::uint64_t{1} << 20);  // no cgroup files: the machine's memory
  // v2: a limit below the machine's lowers it; "max" (none) and nonsense do not.
  put(dir / "v2" / "memory.max", "1073741824\n");
  EXPECT_EQ(format::detail::usable_memory_bytes(dir / "v2", none),
            std::min<std::uint64_t>(machine, 1073741824));
  put(dir / "v2" / "memory.max", "max\n");
  EXPECT_EQ(format::detail::usable_memory_bytes(dir / "v2", none), machine);
  put(dir / "v2" / "memory.max", "-5\n");
  EXPECT_EQ(format::detail::usable_memory_bytes(dir / "v2", none), machine);
  // v1: "no limit" is a number near 2^63, above the machine's memory.
  put(dir / "v1" / "memory" / "memory.limit_in_bytes", "9223372036854771712\n");
  EXPECT_EQ(format::detail::usable_memory_bytes(dir / "v1", none), machine);
  put(dir / "v1" / "memory" / "memory.limit_in_bytes", "536870912\n");
  EXPECT_EQ(format::detail::usable_memory_bytes(dir / "v1", none),
            std::min<std::uint64_t>(machine, 536870912));
}

TEST(UsableMemory, TheProcesssOwnGroupAndItsParentsCount) {
  test::TempDir dir("usable-memory-group");
  const fs::path none = dir / "none";
  const std::uint64_t machine = format::detail::usable_memory_bytes(none, none);
  // v2: the job's group (a batch job's step) and its parent; the lowest limit binds.
  put(dir / "self-v2", "0::/job/step\n");
  put(dir / "v2" / "job" / "memory.max", "805306368\n");
  put(dir / "v2" / "job" / "step" / "memory.max", "max\n");
  EXPECT_EQ(format::detail::usable_memory_bytes(dir / "v2", dir / "self-v2"),
            std::min<std::uint64_t>(machine, 805306368));
  put(dir / "v2" / "job" / "step" / "memory.max", "268435456\n");
  EXPECT_EQ(format::detail::usable_memory_bytes(dir / "v2", dir / "self-v2"),
            std::min<std::uint64_t>(machine, 268435456));
  // v1: the memory controller's line, among others.
  put(dir / "self-v1", "5:cpu,cpuacct:/other\n4:memory:/process_api/abc\n0::/\n");
  put(dir / "v1" / "memory" / "process_api" / "abc" / "memory.limit_in_bytes", "134217728\n");
  put(dir / "v1" / "memory" / "other" / "memory.limit_in_bytes", "1024\n");  // the cpu line's group
  EXPECT_EQ(format::detail::usable_memory_bytes(dir / "v1", dir / "self-v1"),
            std::min<std::uint64_t>(machine, 134217728));
}

}  // namespace
}  // namespace volreel
