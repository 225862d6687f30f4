// resources.cpp: creation of the RAII-owned Vulkan objects of resources.hpp.
#include "volreel/vulkan/resources.hpp"

namespace volreel::vulkan {

Buffer::Buffer(const Context& context, VkDeviceSize size, VkBufferUsageFlags usage,
               VkMemoryPropertyFlags required, VkMemoryPropertyFlags preferred)
    : size_(size) {
  const VkDevice device = context.device();
  if (size == 0) throw Error("vkCreateBuffer: a buffer of 0 bytes", VK_ERROR_INITIALIZATION_FAILED);
  VkBufferCreateInfo info{VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO};
  info.size = size;
  info.usage = usage;
  info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  VkBuffer buffer = VK_NULL_HANDLE;
  check(vkCreateBuffer(device, &info, nullptr, &buffer), "vkCreateBuffer");
  buffer_ = {device, buffer};
  VkMemoryRequirements needs;
  vkGetBufferMemoryRequirements(device, buffer, &needs);
  VkMemoryAllocateInfo alloc{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  alloc.allocationSize = needs.size;
  alloc.memoryTypeIndex = context.find_memory_type(needs.memoryTypeBits, required, preferred);
  flags_ = context.memory_type_flags(alloc.memoryTypeIndex);
  VkDeviceMemory memory = VK_NULL_HANDLE;
  check(vkAllocateMemory(device, &alloc, nullptr, &memory), "vkAllocateMemory");
  memory_ = {device, memory};
  check(vkBindBufferMemory(device, buffer, memory, 0), "vkBindBufferMemory");
  if (flags_ & VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT) {
    void* p = nullptr;
    check(vkMapMemory(device, memory, 0, VK_WHOLE_SIZE, 0, &p), "vkMapMemory");
    mapped_ = static_cast<std::byte*>(p);
  }
}

void Buffer::flush(VkDeviceSize offset, VkDeviceSize size) const {
  if (!mapped_ || (flags_ & VK_MEMORY_PROPERTY_HOST_COHERENT_BIT)) return;
  VkMappedMemoryRange range{VK_STRUCTURE_TYPE_MAPPED_MEMORY_RANGE};
  range.memory = memory_.get();
  range.offset = offset;
  range.size = size;
  check(vkFlushMappedMemoryRanges(memory_.device(), 1, &range), "vkFlushMappedMemoryRanges");
}

void Buffer::invalidate(VkDeviceSize offset, VkDeviceSize size) const {
  if (!mapped_ || (flags_ & VK_MEMORY_PROPERTY_HOST_COHERENT_BIT)) return;
  VkMappedMemoryRange range{VK_STRUCTURE_TYPE_MAPPED_MEMORY_RANGE};
  range.memory = memory_.get();
  range.offset = offset;
  range.size = size;
  check(vkInvalidateMappedMemoryRanges(memory_.device(), 1, &range),
        "vkInvalidateMappedMemoryRanges");
}

Image::Image(const Context& context, const ImageDesc& desc) : desc_(desc) {
  const VkDevice device = context.device();
  VkImageCreateInfo info{VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO};
  info.imageType = desc.type;
  info.format = desc.format;
  info.extent = desc.extent;
  info.mipLevels = 1;
  info.arrayLayers = 1;
  info.samples = VK_SAMPLE_COUNT_1_BIT;
  info.tiling = VK_IMAGE_TILING_OPTIMAL;
  info.usage = desc.usage;
  info.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  info.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  VkImage image = VK_NULL_HANDLE;
  check(vkCreateImage(device, &info, nullptr, &image), "vkCreateImage");
  image_ = {device, image};
  VkMemoryRequirements needs;
  vkGetImageMemoryRequirements(device, image, &needs);
  VkMemoryAllocateInfo alloc{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO};
  alloc.allocationSize = needs.size;
  alloc.memoryTypeIndex =
      context.find_memory_type(needs.memoryTypeBits, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  VkDeviceMemory memory = VK_NULL_HANDLE;
  check(vkAllocateMemory(device, &alloc, nullptr, &memory), "vkAllocateMemory");
  memory_ = {device, memory};
  check(vkBindImageMemory(device, image, memory, 0), "vkBindImageMemory");
  VkImageViewCreateInfo view_info{VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO};
  view_info.image = image;
  view_info.viewType = desc.type == VK_IMAGE_TYPE_3D   ? VK_IMAGE_VIEW_TYPE_3D
                       : desc.type == VK_IMAGE_TYPE_2D ? VK_IMAGE_VIEW_TYPE_2D
                                                       : VK_IMAGE_VIEW_TYPE_1D;
  view_info.format = desc.format;
  view_info.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
  VkImageView view = VK_NULL_HANDLE;
  check(vkCreateImageView(device, &view_info, nullptr, &view), "vkCreateImageView");
  view_ = {device, view};
}

Sampler::Sampler(const Context& context, VkFilter filter, VkSamplerAddressMode address_mode) {
  VkSamplerCreateInfo info{VK_STRUCTURE_TYPE_SAMPLER_CREATE_INFO};
  info.magFilter = filter;
  info.minFilter = filter;
  info.mipmapMode = VK_SAMPLER_MIPMAP_MODE_NEAREST;
  info.addressModeU = info.addressModeV = info.addressModeW = address_mode;
  info.maxLod = 0.0f;
  info.borderColor = VK_BORDER_COLOR_FLOAT_TRANSPARENT_BLACK;
  VkSampler sampler = VK_NULL_HANDLE;
  check(vkCreateSampler(context.device(), &info, nullptr, &sampler), "vkCreateSampler");
  sampler_ = {context.device(), sampler};
}

ShaderModule::ShaderModule(const Context& context, std::span<const std::uint32_t> spirv) {
  VkShaderModuleCreateInfo info{VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO};
  info.codeSize = spirv.size_bytes();
  info.pCode = spirv.data();
  VkShaderModule module = VK_NULL_HANDLE;
  check(vkCreateShaderModule(context.device(), &info, nullptr, &module), "vkCreateShaderModule");
  module_ = {context.device(), module};
}

DescriptorSetLayout::DescriptorSetLayout(const Context& context,
                                         std::span<const VkDescriptorSetLayoutBinding> bindings) {
  VkDescriptorSetLayoutCreateInfo info{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO};
  info.bindingCount = static_cast<std::uint32_t>(bindings.size());
  info.pBindings = bindings.data();
  VkDescriptorSetLayout layout = VK_NULL_HANDLE;
  check(vkCreateDescriptorSetLayout(context.device(), &info, nullptr, &layout),
        "vkCreateDescriptorSetLayout");
  layout_ = {context.device(), layout};
}

ComputePipeline::ComputePipeline(const Context& context, const ShaderModule& shader,
                                 std::span<const VkDescriptorSetLayout> set_layouts,
                                 std::uint32_t push_constant_bytes,
                                 std::span<const std::uint32_t> specialization) {
  const VkDevice device = context.device();
  VkPushConstantRange range{VK_SHADER_STAGE_COMPUTE_BIT, 0, push_constant_bytes};
  VkPipelineLayoutCreateInfo layout_info{VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO};
  layout_info.setLayoutCount = static_cast<std::uint32_t>(set_layouts.size());
  layout_info.pSetLayouts = set_layouts.data();
  layout_info.pushConstantRangeCount = push_constant_bytes ? 1u : 0u;
  layout_info.pPushConstantRanges = &range;
  VkPipelineLayout layout = VK_NULL_HANDLE;
  check(vkCreatePipelineLayout(device, &layout_info, nullptr, &layout), "vkCreatePipelineLayout");
  layout_ = {device, layout};
  VkComputePipelineCreateInfo info{VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO};
  info.stage = {VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO};
  info.stage.stage = VK_SHADER_STAGE_COMPUTE_BIT;
  info.stage.module = shader.handle();
  info.stage.pName = "main";
  std::vector<VkSpecializationMapEntry> entries;
  for (std::uint32_t i = 0; i < specialization.size(); ++i)
    entries.push_back({i, 4 * i, sizeof(std::uint32_t)});
  const VkSpecializationInfo constants{static_cast<std::uint32_t>(entries.size()), entries.data(),
                                       specialization.size_bytes(), specialization.data()};
  if (!specialization.empty()) info.stage.pSpecializationInfo = &constants;
  info.layout = layout;
  VkPipeline pipeline = VK_NULL_HANDLE;
  check(vkCreateComputePipelines(device, VK_NULL_HANDLE, 1, &info, nullptr, &pipeline),
        "vkCreateComputePipelines");
  pipeline_ = {device, pipeline};
}

DescriptorPool::DescriptorPool(const Context& context, std::span<const VkDescriptorPoolSize> sizes,
                               std::uint32_t max_sets) {
  VkDescriptorPoolCreateInfo info{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
  info.maxSets = max_sets;
  info.poolSizeCount = static_cast<std::uint32_t>(sizes.size());
  info.pPoolSizes = sizes.data();
  VkDescriptorPool pool = VK_NULL_HANDLE;
  check(vkCreateDescriptorPool(context.device(), &info, nullptr, &pool), "vkCreateDescriptorPool");
  pool_ = {context.device(), pool};
}

VkDescriptorSet DescriptorPool::allocate(VkDescriptorSetLayout layout) const {
  VkDescriptorSetAllocateInfo info{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO};
  info.descriptorPool = pool_.get();
  info.descriptorSetCount = 1;
  info.pSetLayouts = &layout;
  VkDescriptorSet set = VK_NULL_HANDLE;
  check(vkAllocateDescriptorSets(pool_.device(), &info, &set), "vkAllocateDescriptorSets");
  return set;
}

void write_storage_buffer(VkDevice device, VkDescriptorSet set, std::uint32_t binding,
                          VkBuffer buffer, VkDeviceSize offset, VkDeviceSize range) {
  VkDescriptorBufferInfo info{buffer, offset, range};
  VkWriteDescriptorSet write{VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
  write.dstSet = set;
  write.dstBinding = binding;
  write.descriptorCount = 1;
  write.descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER;
  write.pBufferInfo = &info;
  vkUpdateDescriptorSets(device, 1, &write, 0, nullptr);
}

void write_storage_image(VkDevice device, VkDescriptorSet set, std::uint32_t binding,
                         VkImageView view, VkImageLayout layout) {
  VkDescriptorImageInfo info{VK_NULL_HANDLE, view, layout};
  VkWriteDescriptorSet write{VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
  write.dstSet = set;
  write.dstBinding = binding;
  write.descriptorCount = 1;
  write.descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_IMAGE;
  write.pImageInfo = &info;
  vkUpdateDescriptorSets(device, 1, &write, 0, nullptr);
}

void write_sampled_image(VkDevice device, VkDescriptorSet set, std::uint32_t binding,
                         VkImageView view, VkSampler sampler, VkImageLayout layout) {
  VkDescriptorImageInfo info{sampler, view, layout};
  VkWriteDescriptorSet write{VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET};
  write.dstSet = set;
  write.dstBinding = binding;
  write.descriptorCount = 1;
  write.descriptorType = VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER;
  write.pImageInfo = &info;
  vkUpdateDescriptorSets(device, 1, &write, 0, nullptr);
}

CommandPool::CommandPool(const Context& context, VkCommandPoolCreateFlags flags) {
  VkCommandPoolCreateInfo info{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
  info.flags = flags;
  info.queueFamilyIndex = context.queue_family();
  VkCommandPool pool = VK_NULL_HANDLE;
  check(vkCreateCommandPool(context.device(), &info, nullptr, &pool), "vkCreateCommandPool");
  pool_ = {context.device(), pool};
}

std::vector<VkCommandBuffer> CommandPool::allocate(std::uint32_t count) const {
  VkCommandBufferAllocateInfo info{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
  info.commandPool = pool_.get();
  info.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
  info.commandBufferCount = count;
  std::vector<VkCommandBuffer> buffers(count);
  check(vkAllocateCommandBuffers(pool_.device(), &info, buffers.data()),
        "vkAllocateCommandBuffers");
  return buffers;
}

Fence::Fence(const Context& context, bool signaled) {
  VkFenceCreateInfo info{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
  info.flags = signaled ? VkFenceCreateFlags{VK_FENCE_CREATE_SIGNALED_BIT} : VkFenceCreateFlags{0};
  VkFence fence = VK_NULL_HANDLE;
  check(vkCreateFence(context.device(), &info, nullptr, &fence), "vkCreateFence");
  fence_ = {context.device(), fence};
}

bool Fence::wait(std::uint64_t timeout_ns) const {
  VkFence fence = fence_.get();
  return check(vkWaitForFences(fence_.device(), 1, &fence, VK_TRUE, timeout_ns),
               "vkWaitForFences") == VK_SUCCESS;
}

bool Fence::signaled() const {
  return check(vkGetFenceStatus(fence_.device(), fence_.get()), "vkGetFenceStatus") == VK_SUCCESS;
}

void Fence::reset() const {
  VkFence fence = fence_.get();
  check(vkResetFences(fence_.device(), 1, &fence), "vkResetFences");
}

Semaphore::Semaphore(const Context& context) {
  VkSemaphoreCreateInfo info{VK_STRUCTURE_TYPE_SEMAPHORE_CREATE_INFO};
  VkSemaphore semaphore = VK_NULL_HANDLE;
  check(vkCreateSemaphore(context.device(), &info, nullptr, &semaphore), "vkCreateSemaphore");
  semaphore_ = {context.device(), semaphore};
}

void begin_commands(VkCommandBuffer commands) {
  VkCommandBufferBeginInfo begin{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
  begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
  check(vkBeginCommandBuffer(commands, &begin), "vkBeginCommandBuffer");
}

void end_commands(VkCommandBuffer commands) {
  check(vkEndCommandBuffer(commands), "vkEndCommandBuffer");
}

void memory_barrier(VkCommandBuffer commands, VkPipelineStageFlags src_stages,
                    VkAccessFlags src_access, VkPipelineStageFlags dst_stages,
                    VkAccessFlags dst_access) {
  VkMemoryBarrier barrier{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  barrier.srcAccessMask = src_access;
  barrier.dstAccessMask = dst_access;
  vkCmdPipelineBarrier(commands, src_stages, dst_stages, 0, 1, &barrier, 0, nullptr, 0, nullptr);
}

void image_barrier(VkCommandBuffer commands, VkImage image, VkImageLayout old_layout,
                   VkImageLayout new_layout, VkPipelineStageFlags src_stages,
                   VkAccessFlags src_access, VkPipelineStageFlags dst_stages,
                   VkAccessFlags dst_access) {
  VkImageMemoryBarrier barrier{VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER};
  barrier.srcAccessMask = src_access;
  barrier.dstAccessMask = dst_access;
  barrier.oldLayout = old_layout;
  barrier.newLayout = new_layout;
  barrier.srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  barrier.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  barrier.image = image;
  barrier.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
  vkCmdPipelineBarrier(commands, src_stages, dst_stages, 0, 0, nullptr, 0, nullptr, 1, &barrier);
}

}  // namespace volreel::vulkan
