// The loop's duration histogram (server/histogram.h): 1 us bins to 5 ms, 1 ms bins to
// 1 s, one bin beyond; quantiles are the upper edge of their bin, capped by the exact
// maximum.
#include <cmath>

#include <gtest/gtest.h>

#include "server/histogram.h"

namespace palpate::server {
namespace {

TEST(Histogram, EmptyIsAllZero) {
  Histogram h;
  const auto s = h.summary();
  EXPECT_EQ(s.count, 0u);
  EXPECT_EQ(s.p50, 0.0);
  EXPECT_EQ(s.p99, 0.0);
  EXPECT_EQ(s.max, 0.0);
}

// One sample in each 1 us bin from 0 to 999 us: the q-quantile is the (q n)-th
// sample's bin, reported by its upper edge.
TEST(Histogram, QuantilesOfAUniformDistribution) {
  Histogram h;
  for (int i = 999; i >= 0; --i) h.add(i + 0.5);  // order does not matter
  const auto s = h.summary();
  EXPECT_EQ(s.count, 1000u);
  EXPECT_EQ(s.p50, 500.0);  // the 500th sample, 499.5 us, in [499, 500)
  EXPECT_EQ(s.p99, 990.0);  // the 990th, 989.5 us
  EXPECT_EQ(s.max, 999.5);
}

TEST(Histogram, ASkewedDistribution) {
  Histogram h;
  for (int i = 0; i < 980; ++i) h.add(100.2);
  for (int i = 0; i < 19; ++i) h.add(3000.7);
  h.add(3500.2);
  const auto s = h.summary();
  EXPECT_EQ(s.count, 1000u);
  EXPECT_EQ(s.p50, 101.0);
  EXPECT_EQ(s.p99, 3001.0);  // the 990th sample is one of the 19 in [3000, 3001)
  EXPECT_EQ(s.max, 3500.2);
}

TEST(Histogram, OneSampleIsItsOwnQuantile) {
  Histogram h;
  h.add(123.25);
  const auto s = h.summary();
  EXPECT_EQ(s.p50, 123.25);  // the bin's upper edge, 124, capped by the maximum
  EXPECT_EQ(s.p99, 123.25);
}

// Beyond 5 ms the bins are 1 ms wide.
TEST(Histogram, MillisecondBinsBeyondFiveMilliseconds) {
  Histogram h;
  for (int i = 0; i < 99; ++i) h.add(6500.0);  // in [6 ms, 7 ms)
  h.add(9999.0);
  auto s = h.summary();
  EXPECT_EQ(s.count, 100u);
  EXPECT_EQ(s.p50, 7000.0);
  EXPECT_EQ(s.p99, 7000.0);
  EXPECT_EQ(s.max, 9999.0);
  h.add(5000.0);  // the first coarse bin starts at exactly 5 ms
  h.add(4999.5);  // the last fine bin
  s = h.summary();
  EXPECT_EQ(s.count, 102u);
  Histogram edge;
  edge.add(4999.5);
  edge.add(5000.0);
  edge.add(5000.0);
  EXPECT_EQ(edge.summary().p50, 5000.0);  // [5 ms, 6 ms): upper edge 6000, capped by the maximum 5000
  Histogram fine;
  fine.add(4999.5);
  fine.add(4999.5);
  fine.add(6000.0);
  EXPECT_EQ(fine.summary().p50, 5000.0);  // the last fine bin, [4999, 5000)
  Histogram almost_a_second;
  almost_a_second.add(999999.0);  // [999 ms, 1 s)
  almost_a_second.add(1000.0);
  EXPECT_EQ(almost_a_second.summary().p99, 999999.0);
}

// Everything from 1 s up shares one bin: a quantile there is the maximum.
TEST(Histogram, OneBinBeyondOneSecond) {
  Histogram h;
  for (int i = 0; i < 98; ++i) h.add(10.5);
  h.add(2.5e6);
  h.add(3e6);
  auto s = h.summary();
  EXPECT_EQ(s.count, 100u);
  EXPECT_EQ(s.p50, 11.0);
  EXPECT_EQ(s.p99, 3e6);  // the 99th sample is in the last bin
  EXPECT_EQ(s.max, 3e6);
  Histogram slow;
  for (int i = 0; i < 10; ++i) slow.add(1.5e6);
  s = slow.summary();
  EXPECT_EQ(s.p50, 1.5e6);
  EXPECT_EQ(s.p99, 1.5e6);
  slow.add(INFINITY);
  EXPECT_EQ(slow.summary().count, 11u);
}

TEST(Histogram, NegativeAndNanCountAsZero) {
  Histogram h;
  h.add(-5.0);
  h.add(NAN);
  const auto s = h.summary();
  EXPECT_EQ(s.count, 2u);
  EXPECT_EQ(s.p50, 0.0);
  EXPECT_EQ(s.max, 0.0);
}

TEST(Histogram, ClearStartsAfresh) {
  Histogram h;
  for (int i = 0; i < 100; ++i) h.add(2e6);
  h.clear();
  auto s = h.summary();
  EXPECT_EQ(s.count, 0u);
  EXPECT_EQ(s.max, 0.0);
  EXPECT_EQ(s.p99, 0.0);
  h.add(42.5);
  s = h.summary();
  EXPECT_EQ(s.count, 1u);
  EXPECT_EQ(s.p50, 42.5);
  EXPECT_EQ(s.max, 42.5);
}

}  // namespace
}  // namespace palpate::server
