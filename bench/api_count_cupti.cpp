// bench/api_count_cupti.cpp — ApiCounter over CUPTI's runtime callbacks,
// DeviceTimeline over its activity records.
#include <cuda_profiler_api.h>
#include <cupti.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cxxabi.h>
#include <map>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "bench/api_count.hpp"

namespace marbles::bench {
namespace {

std::atomic<std::uint64_t> g_launches{0}, g_waits{0};

bool is_launch(CUpti_CallbackId id) {
  switch (id) {
    case CUPTI_RUNTIME_TRACE_CBID_cudaLaunch_v3020:
    case CUPTI_RUNTIME_TRACE_CBID_cudaLaunch_ptsz_v7000:
    case CUPTI_RUNTIME_TRACE_CBID_cudaLaunchKernel_v7000:
    case CUPTI_RUNTIME_TRACE_CBID_cudaLaunchKernel_ptsz_v7000:
    case CUPTI_RUNTIME_TRACE_CBID_cudaLaunchKernelExC_v11060:
    case CUPTI_RUNTIME_TRACE_CBID_cudaLaunchKernelExC_ptsz_v11060:
    case CUPTI_RUNTIME_TRACE_CBID_cudaLaunchCooperativeKernel_v9000:
    case CUPTI_RUNTIME_TRACE_CBID_cudaLaunchCooperativeKernel_ptsz_v9000:
    case CUPTI_RUNTIME_TRACE_CBID___cudaLaunchKernel_v13000:
    case CUPTI_RUNTIME_TRACE_CBID___cudaLaunchKernel_ptsz_v13000:
      return true;
    default:
      return false;
  }
}

bool is_wait(CUpti_CallbackId id) {
  switch (id) {
    case CUPTI_RUNTIME_TRACE_CBID_cudaStreamSynchronize_v3020:
    case CUPTI_RUNTIME_TRACE_CBID_cudaStreamSynchronize_ptsz_v7000:
    case CUPTI_RUNTIME_TRACE_CBID_cudaEventSynchronize_v3020:
    case CUPTI_RUNTIME_TRACE_CBID_cudaDeviceSynchronize_v3020:
    case CUPTI_RUNTIME_TRACE_CBID_cudaThreadSynchronize_v3020:
    case CUPTI_RUNTIME_TRACE_CBID_cudaMemcpy_v3020:
    case CUPTI_RUNTIME_TRACE_CBID_cudaFree_v3020:
      return true;
    default:
      return false;
  }
}

// Each runtime function's calls and host time, by callback id. The entry's
// time rides in the call's correlation word to its exit.
struct FunctionTime {
  std::atomic<const char*> name{nullptr};
  std::atomic<std::uint64_t> calls{0}, ns{0};
};
std::array<FunctionTime, CUPTI_RUNTIME_TRACE_CBID_SIZE> g_times;

std::uint64_t host_ns() {
  return static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
          .count());
}

void CUPTIAPI on_call(void*, CUpti_CallbackDomain domain, CUpti_CallbackId id, const void* data) {
  if (domain != CUPTI_CB_DOMAIN_RUNTIME_API) return;
  const auto* call = static_cast<const CUpti_CallbackData*>(data);
  if (call->callbackSite == CUPTI_API_EXIT) {
    if (id < g_times.size() && call->correlationData && *call->correlationData != 0) {
      FunctionTime& f = g_times[id];
      f.ns.fetch_add(host_ns() - *call->correlationData, std::memory_order_relaxed);
      f.calls.fetch_add(1, std::memory_order_relaxed);
      if (!f.name.load(std::memory_order_relaxed)) f.name.store(call->functionName, std::memory_order_relaxed);
    }
    return;
  }
  if (is_launch(id)) g_launches.fetch_add(1, std::memory_order_relaxed);
  else if (is_wait(id)) g_waits.fetch_add(1, std::memory_order_relaxed);
  if (call->correlationData) *call->correlationData = host_ns();  // last: the counting is not the call's time
}

// The activity records' intervals (kernels, copies, sets), as CUPTI hands
// over its buffers: from its own thread, or within cuptiActivityFlushAll.
struct Interval {
  std::uint64_t start = 0, end = 0;
  std::uint32_t name = 0;  // into g_names: a kernel's mangled name, or kMemset / kMemcpy
};
std::mutex g_interval_mutex;  // guards g_intervals and the names
std::vector<Interval> g_intervals;
// Each name once, copied out of the record that carried it (CUPTI does not
// say how long its own string lives).
std::vector<std::string> g_names{"(memset)", "(memcpy)"};
std::unordered_map<std::string, std::uint32_t> g_name_index{{"(memset)", 0}, {"(memcpy)", 1}};
constexpr std::uint32_t kMemset = 0, kMemcpy = 1;
std::uint32_t name_index(const char* name) {  // with g_interval_mutex held
  const auto [at, added] = g_name_index.try_emplace(name ? name : "?", static_cast<std::uint32_t>(g_names.size()));
  if (added) g_names.push_back(at->first);
  return at->second;
}
std::atomic<std::size_t> g_dropped{0};  // records CUPTI could not keep (a full buffer)
std::atomic<bool> g_timeline_live{false};  // tracing is process-wide: one DeviceTimeline at a time
constexpr CUpti_ActivityKind kTraced[] = {CUPTI_ACTIVITY_KIND_CONCURRENT_KERNEL, CUPTI_ACTIVITY_KIND_MEMCPY,
                                          CUPTI_ACTIVITY_KIND_MEMSET};

void CUPTIAPI buffer_requested(uint8_t** buffer, size_t* size, size_t* max_records) {
  constexpr std::size_t kBytes = std::size_t(4) << 20;
  *buffer = static_cast<uint8_t*>(std::aligned_alloc(8, kBytes));
  *size = *buffer ? kBytes : 0;
  *max_records = 0;
}

void CUPTIAPI buffer_completed(CUcontext context, uint32_t stream, uint8_t* buffer, size_t, size_t valid) {
  std::size_t dropped = 0;
  if (cuptiActivityGetNumDroppedRecords(context, stream, &dropped) == CUPTI_SUCCESS) g_dropped += dropped;
  const std::lock_guard<std::mutex> lock(g_interval_mutex);
  const char* last_name = nullptr;  // a kernel's records come in runs: its name looked up once a run
  std::uint32_t last_index = 0;
  CUpti_Activity* record = nullptr;
  while (cuptiActivityGetNextRecord(buffer, valid, &record) == CUPTI_SUCCESS) {
    switch (record->kind) {
      case CUPTI_ACTIVITY_KIND_CONCURRENT_KERNEL: {
        const auto* k = reinterpret_cast<const CUpti_ActivityKernel10*>(record);
        if (!last_name || k->name != last_name) last_name = k->name, last_index = name_index(k->name);
        g_intervals.push_back({k->start, k->end, last_index});
        break;
      }
      case CUPTI_ACTIVITY_KIND_MEMCPY: {
        const auto* c = reinterpret_cast<const CUpti_ActivityMemcpy6*>(record);
        g_intervals.push_back({c->start, c->end, kMemcpy});
        break;
      }
      case CUPTI_ACTIVITY_KIND_MEMSET: {
        const auto* m = reinterpret_cast<const CUpti_ActivityMemset4*>(record);
        g_intervals.push_back({m->start, m->end, kMemset});
        break;
      }
      default:
        break;
    }
  }
  std::free(buffer);
}

}  // namespace

DeviceTimeline::DeviceTimeline() {
  static const bool registered = cuptiActivityRegisterCallbacks(buffer_requested, buffer_completed) == CUPTI_SUCCESS;
  if (!registered || g_timeline_live.exchange(true)) return;  // a second one traces nothing
  for (CUpti_ActivityKind kind : kTraced)
    if (cuptiActivityEnable(kind) != CUPTI_SUCCESS) {
      for (CUpti_ActivityKind k : kTraced) cuptiActivityDisable(k);
      g_timeline_live = false;
      return;
    }
  const std::lock_guard<std::mutex> lock(g_interval_mutex);
  g_intervals.clear();
  g_dropped = 0;
  m_on = true;
}

DeviceTimeline::~DeviceTimeline() {
  if (!m_on) return;
  for (CUpti_ActivityKind kind : kTraced) cuptiActivityDisable(kind);
  cuptiActivityFlushAll(CUPTI_ACTIVITY_FLAG_FLUSH_FORCED);
  {
    const std::lock_guard<std::mutex> lock(g_interval_mutex);
    g_intervals.clear();
  }
  g_timeline_live = false;
}

bool DeviceTimeline::complete() const { return m_on && g_dropped == 0; }

std::uint64_t DeviceTimeline::now() const {
  std::uint64_t t = 0;
  if (m_on) cuptiGetTimestamp(&t);
  return t;
}

std::uint64_t DeviceTimeline::busy_ns(std::uint64_t t0, std::uint64_t t1) {
  if (!m_on) return 0;
  cuptiActivityFlushAll(CUPTI_ACTIVITY_FLAG_FLUSH_FORCED);  // hands over every record made so far, in this call
  std::vector<Interval> in;
  {
    const std::lock_guard<std::mutex> lock(g_interval_mutex);
    for (const Interval& i : g_intervals)
      if (i.start >= t0 && i.start < t1 && i.end > i.start) in.push_back(i);
  }
  std::sort(in.begin(), in.end(), [](const Interval& a, const Interval& b) { return a.start < b.start; });
  std::uint64_t busy = 0, open_start = 0, open_end = 0;
  bool open = false;
  for (const Interval& i : in) {
    if (open && i.start <= open_end) {
      open_end = std::max(open_end, i.end);
      continue;
    }
    if (open) busy += open_end - open_start;
    open_start = i.start, open_end = i.end, open = true;
  }
  if (open) busy += open_end - open_start;
  return busy;
}

// A kernel's name as a reader wants it: demangled, without its parameter
// list, anonymous namespaces, the project's own name and the `cuda`
// namespaces within it (narrowphase::record_sweep_kernel<...>; kernels of
// one name in two folders stay apart).
static std::string readable_kernel(const std::string& mangled) {
  int status = 0;
  char* plain = abi::__cxa_demangle(mangled.c_str(), nullptr, nullptr, &status);
  std::string name = status == 0 && plain ? plain : mangled;
  std::free(plain);
  for (const std::string cut : {"(anonymous namespace)::", "marbles::", "::cuda::", "cuda::"}) {
    const char* keep = cut[0] == ':' ? "::" : "";  // "::cuda::" joins what stood either side
    for (std::size_t at; (at = name.find(cut)) != std::string::npos;) name.replace(at, cut.size(), keep);
  }
  // The parameter list: from the first '(' at template depth 0.
  int depth = 0;
  for (std::size_t i = 0; i < name.size(); ++i) {
    if (name[i] == '<') ++depth;
    else if (name[i] == '>') --depth;
    else if (name[i] == '(' && depth == 0 && i > 0) {
      name.resize(i);
      break;
    }
  }
  if (name.rfind("void ", 0) == 0) name.erase(0, 5);
  return name;
}

std::vector<KernelTime> DeviceTimeline::kernels(std::uint64_t t0, std::uint64_t t1) {
  std::vector<KernelTime> out;
  if (!m_on) return out;
  cuptiActivityFlushAll(CUPTI_ACTIVITY_FLAG_FLUSH_FORCED);
  std::map<std::string, KernelTime> merged;  // one entry per readable name
  {
    const std::lock_guard<std::mutex> lock(g_interval_mutex);
    std::map<std::uint32_t, KernelTime> by_name;  // by the mangled name's index
    for (const Interval& i : g_intervals)
      if (i.start >= t0 && i.start < t1 && i.end > i.start) {
        KernelTime& k = by_name[i.name];
        ++k.launches;
        k.ns += i.end - i.start;
      }
    for (const auto& [name, k] : by_name) {
      KernelTime& m = merged[readable_kernel(g_names[name])];
      m.launches += k.launches;
      m.ns += k.ns;
    }
  }
  for (auto& [name, k] : merged) out.push_back({name, k.launches, k.ns});
  std::sort(out.begin(), out.end(), [](const KernelTime& a, const KernelTime& b) {
    return a.ns != b.ns ? a.ns > b.ns : a.kernel < b.kernel;
  });
  return out;
}

ApiCounter::ApiCounter() {
  CUpti_SubscriberHandle subscriber = nullptr;
  if (cuptiSubscribe(&subscriber, on_call, nullptr) != CUPTI_SUCCESS) return;
  if (cuptiEnableDomain(1, subscriber, CUPTI_CB_DOMAIN_RUNTIME_API) != CUPTI_SUCCESS) {
    cuptiUnsubscribe(subscriber);
    return;
  }
  g_launches = 0;
  g_waits = 0;
  for (FunctionTime& f : g_times) f.calls = 0, f.ns = 0;
  m_subscriber = subscriber;
}

ApiCounter::~ApiCounter() {
  if (m_subscriber) cuptiUnsubscribe(static_cast<CUpti_SubscriberHandle>(m_subscriber));
}

ApiCounts ApiCounter::counts() const {
  if (!m_subscriber) return {};
  return {g_launches.load(), g_waits.load()};
}

std::vector<ApiTime> ApiCounter::host_times() const {
  std::vector<ApiTime> times;
  if (!m_subscriber) return times;
  for (const FunctionTime& f : g_times) {
    const std::uint64_t calls = f.calls.load();
    const char* name = f.name.load();
    if (calls > 0) times.push_back({name ? name : "?", calls, f.ns.load()});
  }
  std::sort(times.begin(), times.end(), [](const ApiTime& a, const ApiTime& b) { return a.ns > b.ns; });
  return times;
}

void profiled_steps(bool on) { (void)(on ? cudaProfilerStart() : cudaProfilerStop()); }

}  // namespace marbles::bench
