#pragma once
// Conversion of libfclib's sparse matrix struct to a dense Eigen matrix (fclib_io.cc), exposed
// for the unit tests of the storage conventions.
#include <Eigen/Dense>

#include <string>

struct fclib_matrix;  // <fclib.h>

namespace hapco::fclib::detail {

// Where a triplet matrix keeps its row indices. fclib.h documents `p`; CSparse, and therefore
// Siconos, keep them in `i` (and the column indices in `p`).
enum class TripletRows { kInI, kInP };

// Dense copy of `matrix` (compressed columns nz = -1, compressed rows nz = -2, triplet
// nz >= 0; duplicates summed). `available_values` is how many entries of matrix.x are
// initialised. Throws hapco::InputError starting with `where` on a pointer array that is not
// monotone or exceeds the available values, an index out of range, or a non-finite value.
Eigen::MatrixXd ToDense(const fclib_matrix& matrix, TripletRows triplet_rows,
                        long available_values, const std::string& where);

}  // namespace hapco::fclib::detail
