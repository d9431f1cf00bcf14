// bench/api_count_cupti.cpp — ApiCounter over CUPTI's runtime callbacks.
#include <cuda_profiler_api.h>
#include <cupti.h>

#include <atomic>

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

void CUPTIAPI on_call(void*, CUpti_CallbackDomain domain, CUpti_CallbackId id, const void* data) {
  if (domain != CUPTI_CB_DOMAIN_RUNTIME_API) return;
  if (static_cast<const CUpti_CallbackData*>(data)->callbackSite != CUPTI_API_ENTER) return;
  if (is_launch(id)) g_launches.fetch_add(1, std::memory_order_relaxed);
  else if (is_wait(id)) g_waits.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace

ApiCounter::ApiCounter() {
  CUpti_SubscriberHandle subscriber = nullptr;
  if (cuptiSubscribe(&subscriber, on_call, nullptr) != CUPTI_SUCCESS) return;
  if (cuptiEnableDomain(1, subscriber, CUPTI_CB_DOMAIN_RUNTIME_API) != CUPTI_SUCCESS) {
    cuptiUnsubscribe(subscriber);
    return;
  }
  g_launches = 0;
  g_waits = 0;
  m_subscriber = subscriber;
}

ApiCounter::~ApiCounter() {
  if (m_subscriber) cuptiUnsubscribe(static_cast<CUpti_SubscriberHandle>(m_subscriber));
}

ApiCounts ApiCounter::counts() const {
  if (!m_subscriber) return {};
  return {g_launches.load(), g_waits.load()};
}

void profiled_steps(bool on) { (void)(on ? cudaProfilerStart() : cudaProfilerStop()); }

}  // namespace marbles::bench
