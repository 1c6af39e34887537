#include "test_problems.h"

#include <cmath>
#include <numbers>
#include <random>

namespace hapco::contact::testing {

ContactProblem RandomSpdProblem(int num_contacts, unsigned seed, double coupling,
                                double diagonal_shift) {
  const int n = 3 * num_contacts;
  const double w0 = 1e-3;  // m/N
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  Eigen::MatrixXd b(n, n);
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) b(i, j) = normal(rng);
  }
  ContactProblem p;
  p.flexibility_m_per_n = w0 * (coupling * (b * b.transpose()) / n +
                                diagonal_shift * Eigen::MatrixXd::Identity(n, n));
  // Exact symmetry (the product is symmetric up to round-off only).
  p.flexibility_m_per_n = 0.5 * (p.flexibility_m_per_n + p.flexibility_m_per_n.transpose()).eval();
  p.free_displacement_m.resize(n);
  p.friction_coefficient.resize(num_contacts);
  for (int a = 0; a < num_contacts; ++a) {
    const double mu = 0.2 + 0.4 * uniform(rng);
    p.friction_coefficient(a) = mu;
    const double angle = 2.0 * std::numbers::pi * uniform(rng);
    const double press = 1e-3 * (0.5 + uniform(rng));
    double push = 0.0;
    double normal_part = -press;
    switch (a % 3) {
      case 0: push = 0.2 * mu * press; break;   // well inside the cone: stick
      case 1: push = 3.0 * mu * press; break;   // far outside: slide
      case 2: normal_part = 0.5 * press; push = 0.5 * press; break;  // gap: separate
    }
    p.free_displacement_m.segment<3>(3 * a) =
        Eigen::Vector3d(normal_part, push * std::cos(angle), push * std::sin(angle));
  }
  return p;
}

ContactProblem FoundationPunchProblem(int num_contacts, double push_m, double k_link_n_per_m) {
  const int m = num_contacts;
  const double k_n = 1000.0, k_t = 600.0, k_link = k_link_n_per_m;  // N/m
  Eigen::MatrixXd k = Eigen::MatrixXd::Zero(3 * m, 3 * m);
  for (int a = 0; a < m; ++a) {
    for (int d = 0; d < 3; ++d) {
      const int i = 3 * a + d;
      k(i, i) += d == 0 ? k_n : k_t;
      if (a + 1 < m) {
        const int j = 3 * (a + 1) + d;
        k(i, i) += k_link;
        k(j, j) += k_link;
        k(i, j) -= k_link;
        k(j, i) -= k_link;
      }
    }
  }
  ContactProblem p;
  p.flexibility_m_per_n = k.inverse();
  p.flexibility_m_per_n = 0.5 * (p.flexibility_m_per_n + p.flexibility_m_per_n.transpose()).eval();
  p.free_displacement_m.resize(3 * m);
  p.friction_coefficient = Eigen::VectorXd::Constant(m, 0.4);
  for (int a = 0; a < m; ++a) {
    const double x = m > 1 ? static_cast<double>(a) / (m - 1) : 0.0;  // 0..1 along the chain
    const double gap = -1e-3 + 1.6e-3 * x * x;  // pressed at x=0, open near x=1
    const double angle = 0.3 * x;
    p.free_displacement_m.segment<3>(3 * a) =
        Eigen::Vector3d(gap, push_m * std::cos(angle), push_m * std::sin(angle));
  }
  return p;
}

std::vector<NamedProblem> MatrixProblems() {
  std::vector<NamedProblem> set;
  {
    // One contact, decoupled block, pushed beyond the cone: slides.
    ContactProblem p;
    p.flexibility_m_per_n = Eigen::Vector3d(1e-3, 2e-3, 2e-3).asDiagonal();
    p.free_displacement_m = Eigen::Vector3d(-1e-3, 1.5e-3, -0.5e-3);
    p.friction_coefficient = Eigen::VectorXd::Constant(1, 0.3);
    set.push_back({"single_slide", p});
  }
  set.push_back({"random_spd_12", RandomSpdProblem(12, 7u)});
  set.push_back({"random_spd_40_coupled", RandomSpdProblem(40, 11u, 2.0, 3.0)});
  set.push_back({"foundation_punch_25", FoundationPunchProblem(25, 4e-4)});
  return set;
}

}  // namespace hapco::contact::testing
