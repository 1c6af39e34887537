// Nearest-rank quantiles, checked against values worked out by hand.
#include "common/statistics.h"

#include <gtest/gtest.h>

#include <vector>

namespace hapco {
namespace {

TEST(Quantile, NearestRank) {
  std::vector<double> v{5, 1, 4, 2, 3};
  EXPECT_EQ(Quantile(&v, 0.5), 3);  // rank ceil(2.5) = 3
  EXPECT_EQ(Quantile(&v, 1.0), 5);
  EXPECT_EQ(Quantile(&v, 0.0), 1);
  EXPECT_EQ(Quantile(&v, 0.99), 5);  // rank ceil(4.95) = 5
  EXPECT_EQ(Quantile(&v, 0.2), 1);   // rank 1
  EXPECT_EQ(Quantile(&v, 0.21), 2);  // rank ceil(1.05) = 2
  EXPECT_EQ(Quantile(&v, 7.0), 5);   // clamped
  std::vector<double> empty;
  EXPECT_EQ(Quantile(&empty, 0.5), 0);
}

TEST(Quantile, OfACopyLeavesTheSamplesInOrder) {
  const std::vector<double> v{3, 1, 2};
  EXPECT_EQ(QuantileOf(v, 0.5), 2);
  EXPECT_EQ(v, (std::vector<double>{3, 1, 2}));
}

}  // namespace
}  // namespace hapco
