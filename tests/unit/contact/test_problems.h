#pragma once
// Contact problems for the tests, built from independent SPD matrices (no solver involved).
// Scales: W ~ 1e-3 m/N (a soft body), ũ ~ 1e-3 m, so forces are ~1 N.
#include <string>
#include <vector>

#include "contact/problem.h"

namespace hapco::contact::testing {

// W = w0 (coupling · B Bᵀ / (3m) + c I) with B standard normal (fixed seed), so the condition
// number is about (4 coupling + c)/c. Contacts cycle through pressed-and-pushed-lightly
// (stick), pressed-and-pushed-hard (slide) and gap (separate); μ in [0.2, 0.6].
ContactProblem RandomSpdProblem(int num_contacts, unsigned seed, double coupling = 1.0,
                                double diagonal_shift = 3.0);

// Rigid flat punch on a discrete elastic foundation (1-D chain, analytical stiffness): each
// point has a ground spring (k_n normal, k_t tangential) and springs to its neighbours
// (k_link in every direction), K is tridiagonal per direction and W = K⁻¹. The punch presses
// with a tilt (one end lifts off) and pushes tangentially with a slowly turning direction,
// so the chain has separated, sliding and stuck points (partial slip). Links much stiffer than
// the ground (k_link >> 1000 N/m) couple the points strongly, as a soft organ under a stiffer
// skin: every contact's displacement then depends on all the others' forces.
ContactProblem FoundationPunchProblem(int num_contacts, double push_m, double k_link_n_per_m = 400.0);

struct NamedProblem {
  std::string name;
  ContactProblem problem;
};
// The problem set of the data × solver matrix.
std::vector<NamedProblem> MatrixProblems();

}  // namespace hapco::contact::testing
