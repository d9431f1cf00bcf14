// bench/api_count_none.cpp — ApiCounter and DeviceTimeline in a build without
// CUPTI: they count and trace nothing.
#include "bench/api_count.hpp"

namespace marbles::bench {

ApiCounter::ApiCounter() = default;
ApiCounter::~ApiCounter() = default;
ApiCounts ApiCounter::counts() const { return {}; }
std::vector<ApiTime> ApiCounter::host_times() const { return {}; }

DeviceTimeline::DeviceTimeline() = default;
DeviceTimeline::~DeviceTimeline() = default;
bool DeviceTimeline::complete() const { return false; }
std::uint64_t DeviceTimeline::now() const { return 0; }
std::uint64_t DeviceTimeline::busy_ns(std::uint64_t, std::uint64_t) { return 0; }
std::vector<KernelTime> DeviceTimeline::kernels(std::uint64_t, std::uint64_t) { return {}; }

void profiled_steps(bool) {}

}  // namespace marbles::bench
