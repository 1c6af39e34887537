// Global FCLIB problems (M v = H r + f, u = H^T v + w) and round-off-asymmetric local W:
// the files of scripts/make_siconos_style_fclib.py read as the problem typed in here by hand,
// in every layout other tools write; the Delassus operator against a dense reference; the
// global residual; round trips.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <Eigen/SparseCore>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "common/error.h"
#include "contact/global_problem.h"
#include "contact/solver.h"
#include "delassus/delassus.h"
#include "fclib/fclib_io.h"
#include "fclib_test_util.h"

namespace hapco::fclib {
namespace {

using testing::DataFile;
using testing::KnownProblem;
using testing::ScratchFile;

// The script's GM, GH, GF, GW, GMU, typed in by hand.
Eigen::MatrixXd KnownM() {
  Eigen::MatrixXd m(5, 5);
  // clang-format off
  m << 4.0, 1.0, 0.0, 0.0, 0.0,
       1.0, 3.0, 0.0, 0.0, 0.0,
       0.0, 0.0, 2.0, 0.0, 0.0,
       0.0, 0.0, 0.0, 5.0, 0.5,
       0.0, 0.0, 0.0, 0.5, 2.5;
  // clang-format on
  return m;
}
Eigen::MatrixXd KnownH() {
  Eigen::MatrixXd h = Eigen::MatrixXd::Zero(5, 6);
  h(0, 0) = 1.0;
  h(1, 1) = 1.0;
  h(2, 2) = 1.0;
  h(3, 3) = 1.0;
  h(4, 4) = 0.8;
  h(2, 5) = -0.6;
  h(4, 3) = 0.25;
  return h;
}

contact::GlobalContactProblem KnownGlobal() {
  contact::GlobalContactProblem p;
  p.m = KnownM().sparseView();
  p.h = KnownH().sparseView();
  p.f.resize(5);
  p.f << -1.0, 0.5, -0.5, -2.0, 0.25;
  p.w.resize(6);
  p.w << 0.1, 0.0, 0.0, -0.05, 0.0, 0.0;
  p.mu.resize(2);
  p.mu << 0.4, 0.7;
  return p;
}

void ExpectSameGlobal(const contact::GlobalContactProblem& expected, const contact::GlobalContactProblem& actual) {
  EXPECT_EQ(Eigen::MatrixXd(expected.m), Eigen::MatrixXd(actual.m));
  EXPECT_EQ(Eigen::MatrixXd(expected.h), Eigen::MatrixXd(actual.h));
  EXPECT_EQ(expected.f, actual.f);
  EXPECT_EQ(expected.w, actual.w);
  EXPECT_EQ(expected.mu, actual.mu);
}

std::string MessageOf(const std::function<void()>& action) {
  try {
    action();
  } catch (const InputError& error) {
    return error.what();
  }
  return "(no InputError)";
}

TEST(FclibGlobal, EveryWritersLayoutReadsAsTheTypedProblem) {
  struct Case {
    const char* file;
    MatrixStorage storage;
    TripletReading reading;
  };
  for (const Case& c : {Case{"siconos_global_triplet.hdf5", MatrixStorage::kTriplet, TripletReading::kRowsInI},
                        Case{"documented_global_triplet.hdf5", MatrixStorage::kTriplet, TripletReading::kRowsInP},
                        Case{"csc_global.hdf5", MatrixStorage::kCompressedColumns, TripletReading::kNotTriplet}}) {
    SCOPED_TRACE(c.file);
    EXPECT_EQ(ReadFclibKind(DataFile(c.file)), FclibKind::kGlobal);
    FclibGlobalDetails details;
    const contact::GlobalContactProblem read = ReadFclibGlobalProblem(DataFile(c.file), &details);
    ExpectSameGlobal(KnownGlobal(), read);
    EXPECT_EQ(details.m_storage, c.storage);
    EXPECT_EQ(details.h_storage, c.storage);
    EXPECT_EQ(details.h_triplet_reading, c.reading);
    EXPECT_EQ(details.m_stored_entries, 9);
    EXPECT_EQ(details.h_stored_entries, 7);
    EXPECT_NE(details.info.title.find("global test problem"), std::string::npos);
  }
  EXPECT_EQ(ReadFclibKind(DataFile("siconos_triplet.hdf5")), FclibKind::kLocal);
}

// A square H (one particle, one contact, tilted frame: H = [n t1 t2]) fits both triplet
// readings, which give H and its transpose. The reader takes rows in i and hands over the other
// reading; solved with the right one, the particle pressed down with f = (0.5, 0, -19.62) N and
// W = H^T M^-1 H = I / 2 slides: r_n = -2 n.f / 2 = 18.74, r_t = -mu r_n q_t / |q_t| (by hand).
// Read the other way, the same file gave "separating" with r = 0 (a helper session).
TEST(FclibGlobal, ASquareHFitsBothTripletReadingsAndTheOtherIsHandedOver) {
  const double angle = 0.3, mu = 0.3;
  Eigen::Matrix3d h;
  h << 0.0, 1.0, 0.0, std::sin(angle), 0.0, std::cos(angle), std::cos(angle), 0.0, -std::sin(angle);
  for (const char* file : {"square_global_siconos.hdf5", "square_global_documented.hdf5"}) {
    SCOPED_TRACE(file);
    FclibGlobalDetails details;
    contact::GlobalContactProblem read = ReadFclibGlobalProblem(DataFile(file), &details);
    EXPECT_EQ(details.h_triplet_reading, TripletReading::kRowsInI);
    ASSERT_EQ(details.h_other_reading.rows(), 3);
    const bool documented = std::string(file).find("documented") != std::string::npos;
    const Eigen::Matrix3d as_read = Eigen::MatrixXd(read.h), other = Eigen::MatrixXd(details.h_other_reading);
    EXPECT_LT((as_read - (documented ? Eigen::Matrix3d(h.transpose()) : h)).norm(), 1e-15);
    EXPECT_LT((other - (documented ? h : Eigen::Matrix3d(h.transpose()))).norm(), 1e-15);
    if (documented) read.h = details.h_other_reading;  // hapco-solve --triplet-rows p
    const delassus::GlobalToLocal reduction(read);
    contact::SolverParameters params;
    params.fc3d_tolerance = 1e-12;
    params.global_tolerance_m = 1e-300;
    contact::SolverWorkspace workspace;
    contact::SolverResult result;
    ASSERT_EQ(contact::Solve(contact::SolverKind::kReferenceNsgs, reduction.local(), params, &workspace, &result),
              contact::SolverStatus::kConverged);
    const Eigen::Vector3d f(0.5, 0.0, -19.62);
    const Eigen::Vector3d q = h.transpose() * f / 2.0;  // W = I / 2, w = 0
    const double normal = -q(0) / 0.5;
    const Eigen::Vector2d tangential = -mu * normal * q.tail<2>().normalized();
    EXPECT_NEAR(result.force_n(0), normal, 1e-9);
    EXPECT_NEAR(result.force_n(1), tangential(0), 1e-9);
    EXPECT_NEAR(result.force_n(2), tangential(1), 1e-9);
  }
  // An H whose triplets fit one reading only hands over nothing.
  FclibGlobalDetails details;
  (void)ReadFclibGlobalProblem(DataFile("siconos_global_triplet.hdf5"), &details);
  EXPECT_EQ(details.h_other_reading.size(), 0);
}

TEST(FclibGlobal, EqualityConstraintsAndWrongKindAreRefusedWithWhatToDo) {
  EXPECT_NE(MessageOf([] { ReadFclibGlobalProblem(DataFile("bad_global_with_g.hdf5")); })
                .find("has equality constraints (/fclib_global/G and b"),
            std::string::npos);
  EXPECT_NE(MessageOf([] { ReadFclibLocalProblem(DataFile("csc_global.hdf5")); }).find("ReadFclibGlobalProblem"),
            std::string::npos);
  EXPECT_NE(MessageOf([] { ReadFclibGlobalProblem(DataFile("siconos_triplet.hdf5")); }).find("ReadFclibLocalProblem"),
            std::string::npos);
  EXPECT_NE(MessageOf([] { ReadFclibKind(DataFile("bad_not_fclib.hdf5")); }).find("not an FCLIB problem"),
            std::string::npos);
}

TEST(FclibGlobal, ProblemAndSolutionRoundTripBitExact) {
  const std::string path = ScratchFile(".hdf5");
  WriteFclibGlobalProblem(path, KnownGlobal(), FclibInfo{"round trip", "", ""});
  FclibGlobalDetails details;
  ExpectSameGlobal(KnownGlobal(), ReadFclibGlobalProblem(path, &details));
  EXPECT_EQ(details.info.title, "round trip");
  EXPECT_FALSE(ReadFclibGlobalSolution(path).has_value());
  FclibGlobalSolution solution;
  solution.velocity = Eigen::VectorXd::LinSpaced(5, -1.0, 1.0);
  solution.force = Eigen::VectorXd::LinSpaced(6, 0.5, 3.0);
  solution.local_velocity = Eigen::VectorXd::LinSpaced(6, 2.0, -2.0);
  WriteFclibGlobalSolution(path, solution);
  WriteFclibGlobalSolution(path, solution);  // replacing a solution works
  const auto back = ReadFclibGlobalSolution(path);
  ASSERT_TRUE(back.has_value());
  EXPECT_EQ(back->velocity, solution.velocity);
  EXPECT_EQ(back->force, solution.force);
  EXPECT_EQ(back->local_velocity, solution.local_velocity);
  FclibGlobalSolution wrong = solution;
  wrong.velocity.resize(4);
  EXPECT_THROW(WriteFclibGlobalSolution(path, wrong), InputError);
}

// A random sparse SPD M (a chain of coupled dofs) and a sparse H.
contact::GlobalContactProblem RandomGlobal(int n, int contacts, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Eigen::Triplet<double>> m_entries, h_entries;
  for (int i = 0; i < n; ++i) {
    m_entries.emplace_back(i, i, 4.0 + u(rng));
    if (i + 1 < n) {
      const double c = 0.9 * u(rng);
      m_entries.emplace_back(i, i + 1, c);
      m_entries.emplace_back(i + 1, i, c);
    }
  }
  for (int col = 0; col < 3 * contacts; ++col) {
    for (int k = 0; k < 3; ++k) h_entries.emplace_back(static_cast<int>(rng() % n), col, u(rng));
  }
  contact::GlobalContactProblem p;
  p.m.resize(n, n);
  p.m.setFromTriplets(m_entries.begin(), m_entries.end());
  p.h.resize(n, 3 * contacts);
  p.h.setFromTriplets(h_entries.begin(), h_entries.end());
  p.f = Eigen::VectorXd::NullaryExpr(n, [&] { return u(rng); });
  p.w = Eigen::VectorXd::NullaryExpr(3 * contacts, [&] { return 0.1 * u(rng); });
  p.mu = Eigen::VectorXd::NullaryExpr(contacts, [&] { return 0.5 + 0.4 * u(rng); });
  return p;
}

TEST(Delassus, OperatorAndVelocityMatchADenseReference) {
  const contact::GlobalContactProblem p = RandomGlobal(60, 12, 7);
  const delassus::GlobalToLocal reduction(p, std::size_t{1} << 30);
  // Independent reference: dense Cholesky of M.
  const Eigen::MatrixXd m = Eigen::MatrixXd(p.m), h = Eigen::MatrixXd(p.h);
  const Eigen::LLT<Eigen::MatrixXd> llt(m);
  const Eigen::MatrixXd w_reference = h.transpose() * llt.solve(h);
  const Eigen::VectorXd q_reference = h.transpose() * llt.solve(p.f) + p.w;
  EXPECT_LT((reduction.local().flexibility_m_per_n - w_reference).cwiseAbs().maxCoeff(),
            1e-12 * w_reference.cwiseAbs().maxCoeff());
  EXPECT_LT((reduction.local().free_displacement_m - q_reference).cwiseAbs().maxCoeff(),
            1e-12 * q_reference.cwiseAbs().maxCoeff());
  EXPECT_EQ(reduction.local().friction_coefficient, p.mu);
  EXPECT_EQ(reduction.stats().operator_bytes, sizeof(double) * 36 * 36);
  const Eigen::VectorXd r = Eigen::VectorXd::LinSpaced(36, -1.0, 2.0);
  const Eigen::VectorXd v = reduction.GlobalVelocity(r);
  EXPECT_LT((m * v - h * r - p.f).norm(), 1e-12 * (h * r + p.f).norm());
  // A problem whose W would exceed the memory allowed is refused before it is formed.
  EXPECT_THROW(delassus::GlobalToLocal(p, 1000), InputError);
}

TEST(Delassus, ANonPositiveDefiniteMIsRefused) {
  contact::GlobalContactProblem p = KnownGlobal();
  p.m.coeffRef(0, 1) = 5.0;  // |off-diagonal| > sqrt(4 * 3): indefinite
  p.m.coeffRef(1, 0) = 5.0;
  EXPECT_NE(MessageOf([&] { delassus::GlobalToLocal reduction(p); }).find("not positive definite"),
            std::string::npos);
  contact::GlobalContactProblem half = KnownGlobal();
  half.m.coeffRef(1, 0) = 0.0;  // one triangle only
  EXPECT_NE(MessageOf([&] { contact::ValidateGlobalProblem(half); }).find("M is not symmetric"), std::string::npos);
}

// The local solve's answer, mapped back by v = M^-1 (H r + f), satisfies the global problem as
// FCLIB defines it, checked on M, H, f, w directly; a wrong sign of f would not.
TEST(Delassus, SolvedForcesSatisfyTheGlobalProblem) {
  for (unsigned seed : {1u, 2u, 3u}) {
    const contact::GlobalContactProblem p = RandomGlobal(80, 15, seed);
    const delassus::GlobalToLocal reduction(p);
    contact::SolverParameters params;
    params.fc3d_tolerance = 1e-11;
    params.global_tolerance_m = 1e-300;
    params.max_iterations = 5000;
    contact::SolverWorkspace workspace;
    contact::SolverResult result;
    ASSERT_EQ(contact::Solve(contact::SolverKind::kReferenceNsgs, reduction.local(), params, &workspace, &result),
              contact::SolverStatus::kConverged);
    const Eigen::VectorXd v = reduction.GlobalVelocity(result.force_n);
    const contact::GlobalResidual residual = contact::ComputeGlobalResidual(p, v, result.force_n);
    EXPECT_LT(residual.momentum, 1e-13);
    EXPECT_LT(residual.complementarity, 1e-9);
    EXPECT_GT(result.force_n.cwiseAbs().maxCoeff(), 0.0);  // contacts do carry force
    contact::GlobalContactProblem flipped = p;
    flipped.f = -p.f;
    const Eigen::VectorXd v_flipped = (Eigen::MatrixXd(p.m)).llt().solve(Eigen::MatrixXd(p.h) * result.force_n - p.f);
    EXPECT_GT(contact::ComputeGlobalResidual(p, v_flipped, result.force_n).complementarity, 1e-6);
  }
}

TEST(FclibRoundOff, AsymmetricWithinRoundOffIsReadAsItsSymmetricPartAndKeptAsStored) {
  FclibFileDetails details;
  const contact::ContactProblem read = ReadFclibLocalProblem(DataFile("roundoff_asymmetric_csr.hdf5"), &details);
  Eigen::MatrixXd stored = KnownProblem().flexibility_m_per_n;  // the script's W_ROUNDOFF
  stored(5, 3) = 0.2 + 3e-6;
  stored(6, 3) = 0.25 - 1e-6;
  stored(1, 0) = 0.1 + 2e-7;
  EXPECT_NEAR(details.w_relative_asymmetry, 3e-6 / 3.0, 1e-15);
  EXPECT_EQ(details.stored_problem.flexibility_m_per_n, stored);
  EXPECT_EQ(read.flexibility_m_per_n, 0.5 * (stored + stored.transpose()));
  EXPECT_EQ(read.free_displacement_m, KnownProblem().free_displacement_m);
  // A bit-symmetric file keeps no second copy.
  FclibFileDetails symmetric;
  ReadFclibLocalProblem(DataFile("siconos_dense_csr.hdf5"), &symmetric);
  EXPECT_EQ(symmetric.w_relative_asymmetry, 0.0);
  EXPECT_EQ(symmetric.stored_problem.num_contacts(), 0);
  // The writer copies such a problem as it is; a structural asymmetry stays refused.
  const std::string path = ScratchFile(".hdf5");
  WriteFclibLocalProblem(path, details.stored_problem);
  FclibFileDetails again;
  ReadFclibLocalProblem(path, &again);
  EXPECT_EQ(again.stored_problem.flexibility_m_per_n, stored);
  contact::ContactProblem structural = KnownProblem();
  structural.flexibility_m_per_n(0, 3) *= 1.01;  // 0.5 -> 0.505: 1.7e-3 of max|W|
  EXPECT_THROW(WriteFclibLocalProblem(ScratchFile(".b.hdf5"), structural), InputError);
}

}  // namespace
}  // namespace hapco::fclib
