#pragma once
// FCLIB (HDF5 frictional-contact exchange format, libfclib 3.1) for the local problem
//     u = W r + q,   r_α ∈ K_μα + Signorini/Coulomb,   local coordinates [normal, t1, t2],
// i.e. a contact::ContactProblem with W = flexibility_m_per_n, q = free_displacement_m,
// μ = friction_coefficient (design.md example 6: a failing step becomes a test file).
//
// Reading accepts what other tools write (Siconos Numerics, libfclib itself):
//  - W stored as compressed columns (nz = -1), compressed rows (nz = -2: Siconos writes
//    this for dense and sparse-block W) or triplets (nz >= 0);
//  - triplets: fclib.h documents p = row indices, i = column indices, but Siconos (CSparse)
//    stores rows in i and columns in p. For a square W the two readings are transposes of
//    each other, so they give the same matrix exactly when the stored W is symmetric, which
//    a flexibility must be. We read rows from i (CSparse) and reject an asymmetric result:
//    the convention can neither cause nor repair an asymmetry (e.g. one stored triangle).
//  - duplicate entries are summed (CSparse semantics).
// Not supported (InputError): global problems (/fclib_global), mixed problems with V, R, s,
// spacedim != 3, W not 3m × 3m, more than kMaxContacts contacts (W is dense here).
//
// Every failure throws hapco::InputError naming the file and what is wrong. The file is
// checked with HDF5 before libfclib sees it, because libfclib calls exit(1) on a malformed
// file. HDF5's automatic error-stack printing is switched off process-wide on first use.
#include <Eigen/Dense>

#include <optional>
#include <string>

#include "contact/problem.h"

namespace hapco::fclib {

// Largest problem read (W is stored dense: 3m × 3m doubles, 1.2 GB at this size).
inline constexpr int kMaxContacts = 4000;

// Free text stored in /fclib_local/info (all optional; empty = not written / not present).
struct FclibInfo {
  std::string title;
  std::string description;
  std::string math_info;
};

enum class MatrixStorage { kCompressedColumns, kCompressedRows, kTriplet };
// "compressed columns", "compressed rows", "triplet".
const char* StorageName(MatrixStorage storage);

// What a read found besides the problem (for reports such as hapco-solve's).
struct FclibFileDetails {
  FclibInfo info;
  MatrixStorage w_storage = MatrixStorage::kCompressedColumns;
  int w_stored_entries = 0;  // entries stored for W (nz for triplets, p[n] or p[m] otherwise)
};

// Reads /fclib_local of an FCLIB file. The result passed contact::ValidateProblem.
contact::ContactProblem ReadFclibLocalProblem(const std::string& path,
                                              FclibFileDetails* details = nullptr);

// Writes the problem as a new FCLIB file (an existing file is replaced), W in compressed
// columns with its exact non-zero entries, values bit-exact (float64). Throws InputError if
// the problem fails ValidateProblem or the file cannot be created.
void WriteFclibLocalProblem(const std::string& path, const contact::ContactProblem& problem,
                            const FclibInfo& info = {});

// An FCLIB solution of a local problem: r and u (u = W r + q at an exact solution).
struct FclibSolution {
  Eigen::VectorXd force_n;         // r, 3m, N
  Eigen::VectorXd displacement_m;  // u, 3m, m
};

// Adds /solution {r, u} to an existing FCLIB local-problem file, as fclib_write_solution
// does; a solution already in the file is replaced (libfclib alone refuses to).
void WriteFclibSolution(const std::string& path, const Eigen::VectorXd& force_n,
                        const Eigen::VectorXd& displacement_m);

// The /solution of an FCLIB local-problem file, std::nullopt when the file has none.
std::optional<FclibSolution> ReadFclibSolution(const std::string& path);

// libfclib's own error measure, fclib_merit_local(MERIT_1), an implementation independent
// of HapCo's (used to cross-check contact::Fc3dError). With u = W r + q (recomputed; the
// solution's u is not used) and ρ = 1:
//     merit(r) = ‖ r − Proj_Kμ( r − (u + μ‖u_t‖ n) ) ‖ / (1 + sqrt(‖q‖))
// Same numerator as Fc3dError; only the normalisation differs:
//     merit · (1 + sqrt(‖q‖)) = Fc3dError · max(‖q‖, ‖r‖, ‖u‖).
// (Measured: libfclib divides by 1 + sqrt(‖q‖₂), not 1 + ‖q‖₂, so the merit is not
// scale-free. It also silently treats a triplet-stored W as zero, so W is passed in
// compressed columns here.)
double FclibMeritLocal(const contact::ContactProblem& problem, const Eigen::VectorXd& force_n);

}  // namespace hapco::fclib
