// bench/api_count_none.cpp — ApiCounter in a build without CUPTI: counts nothing.
#include "bench/api_count.hpp"

namespace marbles::bench {

ApiCounter::ApiCounter() = default;
ApiCounter::~ApiCounter() = default;
ApiCounts ApiCounter::counts() const { return {}; }

void profiled_steps(bool) {}

}  // namespace marbles::bench
