#include "common/statistics.h"

#include <algorithm>
#include <cmath>
#include <cstddef>

namespace hapco {

double Quantile(std::vector<double>* values, double p) {
  if (values->empty()) return 0.0;
  const double clamped = std::clamp(p, 0.0, 1.0);
  auto index = static_cast<std::size_t>(std::ceil(clamped * static_cast<double>(values->size())));
  index = index == 0 ? 0 : index - 1;
  std::nth_element(values->begin(), values->begin() + static_cast<std::ptrdiff_t>(index), values->end());
  return (*values)[index];
}

}  // namespace hapco
