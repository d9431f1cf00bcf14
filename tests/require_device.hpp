// tests/require_device.hpp — how a `gpu`-labelled test skips: without a
// usable CUDA device (cuda_device() counts any failure of the runtime or
// driver as none) it stops there, saying so.
#pragma once

#include <gtest/gtest.h>

#include "core/device.hpp"

#define REQUIRE_DEVICE()                                                                   \
  do {                                                                                     \
    if (!::marbles::cuda_device().available) GTEST_SKIP() << "skipped: no CUDA device";  \
  } while (0)
