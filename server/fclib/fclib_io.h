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
//  - duplicate entries are summed (CSparse semantics);
//  - W symmetric only up to round-off (assembled in floating point, or from iterative solves):
//    accepted up to kMaxRelativeAsymmetry, the problem gets the symmetric part (W + Wᵀ)/2 and
//    FclibFileDetails keeps the W as stored (see there).
// Not supported (InputError): mixed problems with V, R, s, spacedim != 3, W not 3m × 3m, more
// than kMaxContacts contacts (W is dense here). Global problems: see the second half below.
//
// Every failure throws hapco::InputError naming the file and what is wrong. The file is
// checked with HDF5 before libfclib sees it, because libfclib calls exit(1) on a malformed
// file. Every access to an existing file (reads, a solution written into it) runs in a worker
// process forked on first use, because HDF5 itself crashes, loops or grows without bound on
// some corrupt files: only the parsed result comes back (fclib_io.cc, docs/fuzzing.md). Not
// for use from several threads at once. HDF5's automatic error-stack printing is switched off
// process-wide on first use.
#include <string_view>
#include <Eigen/Dense>

#include <optional>
#include <string>

#include "contact/global_problem.h"
#include "contact/problem.h"

namespace hapco::fclib {

// Largest problem read (W is stored dense: 3m × 3m doubles, 1.2 GB at this size).
inline constexpr int kMaxContacts = 4000;

// Largest accepted max|W − Wᵀ| / max|W| of a stored W. Why 1e-4: a W assembled with direct
// solves is symmetric to ~1e-16·cond(K) (1e-12 at most on our meshes); writers that compute W
// with iterative solves leave an asymmetry of the order of their solve tolerance (1e-8..1e-5;
// a file seen in the wild differs by ~1e-6 relative: W(7,6) = -0.160679, W(6,7) = -0.16068).
// Every structural fault instead — one triangle stored, a transposed or mis-signed block, a
// lost entry — makes some entry differ from its mirror by O(1) of itself, i.e. far above 1e-4
// of max|W| for any entry that matters. Solving with the symmetric part changes u = W r + q by
// the skew part times r, at most 1e-4·max|W|·‖r‖₁; hapco-solve removes that residual by
// refining the solution on the stored W (the solvers do not need W symmetric: they update u
// by columns), so the answer is judged on the file's own W.
inline constexpr double kMaxRelativeAsymmetry = 1e-4;
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
  // max|W − Wᵀ| / max|W| of the stored W (0 for a bit-symmetric one), dimensionless.
  double w_relative_asymmetry = 0.0;
  // The problem as stored when W is not bit-symmetric (its W is the file's, q and μ the same);
  // empty (0 contacts) otherwise. Not validated by contact::ValidateProblem (asymmetric W).
  contact::ContactProblem stored_problem;
};

// Reads /fclib_local of an FCLIB file. The result passed contact::ValidateProblem; its W is the
// symmetric part of the stored one (identical when the stored W is symmetric).
contact::ContactProblem ReadFclibLocalProblem(const std::string& path,
                                              FclibFileDetails* details = nullptr);

// Writes the problem as a new FCLIB file (an existing file is replaced), W in compressed
// columns with its exact non-zero entries, values bit-exact (float64). Throws InputError if
// the problem fails ValidateProblem (W may be asymmetric within kMaxRelativeAsymmetry: a copy
// of a stored problem is written as it was) or the file cannot be created.
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

// max|W − Wᵀ| / max|W| (0 for W = 0), dimensionless.
double RelativeAsymmetry(const Eigen::MatrixXd& w);

// --- Global problems (/fclib_global: M, H, f, w, mu; contact/global_problem.h) ---

// Which problem an FCLIB file holds (checked like every read: a corrupt file is an InputError).
enum class FclibKind { kLocal, kGlobal };
FclibKind ReadFclibKind(const std::string& path);

// How a triplet-stored H was read: its row indices in `i` (CSparse, as Siconos writes) or in
// `p` (as fclib.h documents). The reading whose indices fit is taken, CSparse's when both fit
// (M is symmetric: both readings agree). Both fit whenever H is square (n = 3n_c: a particle
// per contact) or its indices are small; if the two readings then differ, the file does not
// say which is meant: FclibGlobalDetails::h_other_reading holds the other one (a helper's
// square H written to fclib.h's comment was read transposed and solved to a wrong answer
// without a word).
enum class TripletReading { kNotTriplet, kRowsInI, kRowsInP };

struct FclibGlobalDetails {
  FclibInfo info;
  MatrixStorage m_storage = MatrixStorage::kCompressedColumns;
  MatrixStorage h_storage = MatrixStorage::kCompressedColumns;
  TripletReading h_triplet_reading = TripletReading::kNotTriplet;
  // Non-empty when the other triplet reading of H also fits and gives another matrix: H as
  // that reading gives it (rows in `p` when h_triplet_reading is kRowsInI).
  Eigen::SparseMatrix<double> h_other_reading;
  int m_stored_entries = 0, h_stored_entries = 0;
  double m_relative_asymmetry = 0.0;  // max|M − Mᵀ| / max|M| as stored
};

// Reads /fclib_global of an FCLIB file; the result passed contact::ValidateGlobalProblem.
// Refused with an InputError naming what to change: equality constraints (G, b: the mixed
// problem GM3DFC with multipliers λ), spacedim != 3, more than kMaxContacts contacts, sizes
// that do not match (M n×n, H n×3n_c, f n, w 3n_c, mu n_c), non-finite values.
contact::GlobalContactProblem ReadFclibGlobalProblem(const std::string& path,
                                                     FclibGlobalDetails* details = nullptr);

// Writes a global problem as a new FCLIB file (replacing one), M and H in compressed columns.
void WriteFclibGlobalProblem(const std::string& path, const contact::GlobalContactProblem& problem,
                             const FclibInfo& info = {});

// An FCLIB solution of a global problem: v (n), r and u (3n_c), u = Hᵀ v + w.
struct FclibGlobalSolution {
  Eigen::VectorXd velocity;      // v
  Eigen::VectorXd force;         // r
  Eigen::VectorXd local_velocity;  // u
};
// Adds /solution {v, u, r} to an FCLIB global-problem file (replacing one already there).
void WriteFclibGlobalSolution(const std::string& path, const FclibGlobalSolution& solution);
// The /solution of a global-problem file, std::nullopt when it has none.
std::optional<FclibGlobalSolution> ReadFclibGlobalSolution(const std::string& path);

// For coverage-guided fuzzing (tests/fuzz/fclib_local_target.cc): the reads run in the worker
// process, whose coverage an in-process fuzzer does not see. A harness sets these before the
// first read: `reset` and `collect` run in the worker before and after each request, and the
// bytes `collect` returns go back with the answer to `merge`, in the reading process.
struct WorkerCoverageHooks {
  void (*reset)() = nullptr;
  std::string (*collect)() = nullptr;
  void (*merge)(std::string_view coverage) = nullptr;
};
void SetWorkerCoverageHooks(const WorkerCoverageHooks& hooks);

}  // namespace hapco::fclib
