// vulkan_test_util.hpp: one Vulkan context shared by the tests of a run, with validation on; a
// test without a device is skipped with the reason, and any validation message fails it.
#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <string>

#include "volreel/vulkan/context.hpp"

namespace volreel::test {

/// Owns the shared context: made by the first test that needs it, destroyed when the test
/// program's environment is torn down (before exit, so that leak checkers see it released).
class VulkanEnvironment : public ::testing::Environment {
 public:
  /// The shared context, or nullptr with the reason in `why` when there is no Vulkan device.
  static vulkan::Context* context(std::string* why) {
    if (!tried_) {
      tried_ = true;
      try {
        vulkan::ContextOptions options;
        options.validation = vulkan::Validation::on;
        context_ = std::make_unique<vulkan::Context>(options);
      } catch (const vulkan::NoDeviceError& e) {
        reason_ = e.what();
      }
    }
    if (why) *why = reason_;
    return context_.get();
  }
  void TearDown() override { context_.reset(); }

 private:
  static inline std::unique_ptr<vulkan::Context> context_;
  static inline std::string reason_;
  static inline bool tried_ = false;
};

inline vulkan::Context* vulkan_context(std::string* why) {
  return VulkanEnvironment::context(why);
}

/// Base of every test that needs a device: skips without one; fails on validation messages.
class VulkanTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string why;
    context_ = vulkan_context(&why);
    if (!context_) GTEST_SKIP() << "no Vulkan device, test skipped: " << why;
    context_->clear_validation_messages();
  }
  void TearDown() override {
    if (!context_) return;
    for (const vulkan::ValidationMessage& m : context_->validation_messages())
      ADD_FAILURE() << "Vulkan validation: " << m.text;
  }
  vulkan::Context& context() { return *context_; }

 private:
  vulkan::Context* context_ = nullptr;
};

}  // namespace volreel::test
