#!/usr/bin/env python3
"""Writes the small FCLIB test files in tests/data/fclib/ (run from anywhere; needs python3-h5py).

The files mirror the HDF5 layout that libfclib's fclib_write_local produces (checked with
h5dump against libfclib 3.1): groups /fclib_local/{W,vectors,info}, int32 1-element datasets
for sizes, float64 data, fixed-length NUL-terminated ASCII strings for the info text. Siconos
Numerics writes local problems through that same function, so what differs between tools is
only the CONTENT of W (fclib_matrix fields nzmax, m, n, p, i, x, nz):
  - Siconos, dense W (frictionContact_fclib_write, NM_DENSE): compressed rows (nz = -2),
    nzmax = m*n, every entry stored, p = row pointers, i = column indices;
  - Siconos, sparse-block W (NM_SPARSE_BLOCK -> SBM_to_sparse): compressed rows of the
    non-zero 3x3 blocks, zeros inside a stored block included;
  - Siconos/CSparse triplet: rows in `i`, columns in `p` (fclib.h documents the opposite),
    the arrays written with nz entries while nzmax may be larger (CSparse growth);
  - fclib.h's documented triplet: rows in `p`, columns in `i`;
  - compressed columns (nz = -1), which is what HapCo writes.
Siconos also stores the number of degrees of freedom as an int attribute of /fclib_local/info.

Every local problem is the same hand-written 3-contact problem (W 9x9, q, mu below), copied by
hand into tests/unit/fclib/fclib_io_test.cc. The bad_*.hdf5 files each break one rule.
roundoff_asymmetric_csr.hdf5 stores that W with a few mirrored entries differing by ~1e-6 of
max|W| (what writers computing W with iterative solves leave; compressed rows).

Global problems (/fclib_global: M v = H r + f, u = H^T v + w) use the hand-written 5-dof,
2-contact problem GM, GH, GF, GW, GMU below (copied by hand into the tests), in three layouts:
Siconos' triplets (rows in i, columns in p, nzmax = nz: globalFrictionContact_fclib_write),
fclib.h's documented triplets (rows in p) and compressed columns. H is 5 x 6 with an entry in
column 5, so only one triplet reading fits each file. bad_global_with_g.hdf5 adds an equality
constraint (G, b); bad_global.hdf5 (the name is historical) is a valid 3-dof, 1-contact problem.
"""
import os
import sys

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fclib_h5 import doubles, fixed_string, int1, ints, write_matrix  # noqa: E402,F401

# The known problem (local coordinates [normal, t1, t2] per contact). Symmetric, strictly
# diagonally dominant (hence positive definite); block (0,2) is zero.
W = np.zeros((9, 9))
W[0:3, 0:3] = [[2.0, 0.1, 0.0], [0.1, 1.0, 0.0], [0.0, 0.0, 1.0]]
W[3:6, 3:6] = [[3.0, 0.0, 0.2], [0.0, 1.5, 0.0], [0.2, 0.0, 1.5]]
W[6:9, 6:9] = [[1.0, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 0.5]]
W[0:3, 3:6] = [[0.5, 0.0, 0.0], [0.0, 0.25, 0.0], [0.0, 0.0, 0.0]]
W[3:6, 6:9] = [[0.25, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.1]]
W[3:6, 0:3] = W[0:3, 3:6].T
W[6:9, 3:6] = W[3:6, 6:9].T
Q = np.array([-1.0, 0.5, -0.25, -0.5, 0.1, 0.0, 0.75, 0.0, 0.0])
MU = np.array([0.3, 0.5, 0.8])
assert np.array_equal(W, W.T)

# Round-off asymmetry: mirrored entries off by up to 3e-6 (max|W| = 3: relative 1e-6).
W_ROUNDOFF = W.copy()
W_ROUNDOFF[5, 3] = 0.2 + 3e-6
W_ROUNDOFF[6, 3] = 0.25 - 1e-6
W_ROUNDOFF[1, 0] = 0.1 + 2e-7

# The known global problem: M symmetric positive definite (diagonally dominant), H 5 x 6.
GM = np.array([[4.0, 1.0, 0.0, 0.0, 0.0],
               [1.0, 3.0, 0.0, 0.0, 0.0],
               [0.0, 0.0, 2.0, 0.0, 0.0],
               [0.0, 0.0, 0.0, 5.0, 0.5],
               [0.0, 0.0, 0.0, 0.5, 2.5]])
GH = np.zeros((5, 6))
GH[0, 0] = 1.0; GH[1, 1] = 1.0; GH[2, 2] = 1.0          # contact 0 on dofs 0..2
GH[3, 3] = 1.0; GH[4, 4] = 0.8; GH[2, 5] = -0.6; GH[4, 3] = 0.25  # contact 1 on dofs 2..4
GF = np.array([-1.0, 0.5, -0.5, -2.0, 0.25])
GW = np.array([0.1, 0.0, 0.0, -0.05, 0.0, 0.0])
GMU = np.array([0.4, 0.7])

# A square H (n = 3 n_c): one particle of mass 2 (M = 2 I) on one contact whose frame is tilted
# 0.3 rad about x, H = [n t1 t2] (not symmetric). Its triplets fit both readings, which give H
# and its transpose: the file alone does not say which is meant (a helper session).
SQ_ANGLE = 0.3
SQ_M = 2.0 * np.eye(3)
SQ_H = np.array([[0.0, 1.0, 0.0],
                 [np.sin(SQ_ANGLE), 0.0, np.cos(SQ_ANGLE)],
                 [np.cos(SQ_ANGLE), 0.0, -np.sin(SQ_ANGLE)]])
SQ_F = np.array([0.5, 0.0, -19.62])
SQ_W = np.zeros(3)
SQ_MU = np.array([0.3])
SQUARE = (SQ_M, SQ_H, SQ_F, SQ_W, SQ_MU, "HapCo square-H global test problem")
assert np.array_equal(GM, GM.T) and np.all(np.linalg.eigvalsh(GM) > 0)




def csr(a, keep):
    """Compressed rows of the entries where keep[r, c] is true (row pointers p, columns i)."""
    p, i, x = [0], [], []
    for r in range(a.shape[0]):
        for c in range(a.shape[1]):
            if keep[r, c]:
                i.append(c)
                x.append(a[r, c])
        p.append(len(i))
    return p, i, x


def csc(a):
    p, i, x = [0], [], []
    for c in range(a.shape[1]):
        for r in range(a.shape[0]):
            if a[r, c] != 0.0:
                i.append(r)
                x.append(a[r, c])
        p.append(len(i))
    return p, i, x


def local_file(path, w_writer, q=Q, mu=MU, spacedim=3, info=None, ndof=None):
    with h5py.File(path, "w") as f:
        top = f.create_group("fclib_local")
        int1(top, "spacedim", spacedim)
        w_writer(top.create_group("W"))
        vec = top.create_group("vectors")
        doubles(vec, "q", q)
        doubles(vec, "mu", mu)
        if info is not None:
            g = top.create_group("info")
            for key in ("title", "description", "math_info"):
                if key in info:
                    fixed_string(g, key, info[key])
            if ndof is not None:
                g.attrs.create("numberOfDegreeOfFreedom", ndof, dtype="<i4")


def siconos_dense(g):
    p, i, x = csr(W, np.ones(W.shape, dtype=bool))
    write_matrix(g, 9, 9, -2, 81, p, i, x)


def block_mask():
    keep = np.zeros(W.shape, dtype=bool)
    for a in range(3):
        for b in range(3):
            if np.any(W[3 * a:3 * a + 3, 3 * b:3 * b + 3] != 0.0):
                keep[3 * a:3 * a + 3, 3 * b:3 * b + 3] = True
    return keep


def siconos_sbm(g):
    p, i, x = csr(W, block_mask())
    write_matrix(g, 9, 9, -2, len(x), p, i, x)


def triplet_entries(order):
    """Non-zero (row, col, value), column-major ('col') or row-major ('row') order."""
    rows, cols = np.nonzero(W.T if order == "col" else W)
    if order == "col":
        rows, cols = cols, rows
    return [(int(r), int(c), float(W[r, c])) for r, c in zip(rows, cols)]


def siconos_triplet(g):
    e = triplet_entries("col")
    # CSparse/Siconos: i = row indices, p = column indices; nzmax from CSparse growth.
    write_matrix(g, 9, 9, len(e), len(e) + 4, [c for _, c, _ in e], [r for r, _, _ in e],
                 [v for _, _, v in e])


def documented_triplet(g):
    e = triplet_entries("row")
    # fclib.h: p = row indices, i = column indices.
    write_matrix(g, 9, 9, len(e), len(e), [r for r, _, _ in e], [c for _, c, _ in e],
                 [v for _, _, v in e])


def csc_writer(g):
    p, i, x = csc(W)
    write_matrix(g, 9, 9, -1, len(x), p, i, x)


def scaled_single_contact_writer(scale):
    """One contact, W = scale * I (compressed columns): with q = scale * (-0.5, 0.3, 0) and mu 0.3
    the contact is pressed and slides, r = (0.5, -0.15, 0) at any scale (by hand: sticking would
    need r_t = -0.3, outside the cone 0.15)."""
    def writer(g):
        p, i, x = csc(scale * np.eye(3))
        write_matrix(g, 3, 3, -1, len(x), p, i, x)
    return writer


def upper_triangle_triplet(g):
    e = [t for t in triplet_entries("col") if t[0] <= t[1]]
    write_matrix(g, 9, 9, len(e), len(e), [c for _, c, _ in e], [r for r, _, _ in e],
                 [v for _, _, v in e])


def short_x_csc(g):
    p, i, x = csc(W)
    write_matrix(g, 9, 9, -1, len(x), p, i, x[:-3])  # x shorter than nzmax


def triplets_of(a):
    rows, cols = np.nonzero(a.T)
    rows, cols = cols, rows  # column-major order, as CSparse compresses
    return [(int(r), int(c), float(a[r, c])) for r, c in zip(rows, cols)]


def global_file(path, layout, with_g=False, problem=None):
    """layout: 'siconos' (triplet rows in i), 'documented' (triplet rows in p) or 'csc';
    problem: (M, H, f, w, mu, title), default the 5-dof 2-contact one."""
    gm, gh, gf, gw, gmu, title = problem or (GM, GH, GF, GW, GMU, "HapCo 5-dof 2-contact global test problem")
    def matrix(group, a):
        m, n = a.shape
        if layout == "csc":
            p, i, x = csc(a)
            write_matrix(group, m, n, -1, len(x), p, i, x)
            return
        e = triplets_of(a)
        rows, cols, vals = [r for r, _, _ in e], [c for _, c, _ in e], [v for _, _, v in e]
        if layout == "siconos":
            write_matrix(group, m, n, len(e), len(e), cols, rows, vals)
        else:
            write_matrix(group, m, n, len(e), len(e), rows, cols, vals)
    with h5py.File(path, "w") as f:
        top = f.create_group("fclib_global")
        int1(top, "spacedim", 3)
        matrix(top.create_group("M"), gm)
        matrix(top.create_group("H"), gh)
        vec = top.create_group("vectors")
        doubles(vec, "f", gf)
        doubles(vec, "w", gw)
        doubles(vec, "mu", gmu)
        if with_g:
            matrix(top.create_group("G"), np.array([[1.0], [0.0], [0.0], [0.0], [-1.0]]))
            doubles(vec, "b", [0.0])
        g = top.create_group("info")
        fixed_string(g, "title", "%s (%s layout)" % (title, layout))


def roundoff_csr(g):
    p, i, x = csr(W_ROUNDOFF, block_mask())
    write_matrix(g, 9, 9, -2, len(x), p, i, x)


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = os.path.join(root, "tests", "data", "fclib")
    if len(sys.argv) > 1:
        out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    path = lambda name: os.path.join(out, name)
    info = {"title": "HapCo 3-contact test problem",
            "description": "hand-written W, q, mu (scripts/make_siconos_style_fclib.py)",
            "math_info": "W symmetric positive definite"}

    local_file(path("siconos_dense_csr.hdf5"), siconos_dense, info=info, ndof=18)
    local_file(path("siconos_sbm_csr.hdf5"), siconos_sbm, info=info, ndof=18)
    local_file(path("siconos_triplet.hdf5"), siconos_triplet, info=info, ndof=18)
    local_file(path("documented_triplet.hdf5"), documented_triplet)
    local_file(path("csc_with_solution.hdf5"), csc_writer, info={"title": "with solution"})
    with h5py.File(path("csc_with_solution.hdf5"), "a") as f:
        s = f.create_group("solution")
        doubles(s, "u", [0.5 * k for k in range(9)])
        doubles(s, "r", [1.0 + k for k in range(9)])

    # The same sliding contact in units 1e12 and 1e-12 apart (a helper's hapco-solve called it
    # "separating" resp. "sticking": states judged on one scale for forces and displacements).
    for scale, name in ((1e12, "scaled_1e12_sliding.hdf5"), (1e-12, "scaled_1e-12_sliding.hdf5")):
        local_file(path(name), scaled_single_contact_writer(scale), q=[-0.5 * scale, 0.3 * scale, 0.0], mu=[0.3])
    local_file(path("roundoff_asymmetric_csr.hdf5"), roundoff_csr,
               info={"title": "W symmetric up to round-off (1e-6 relative)"})
    global_file(path("siconos_global_triplet.hdf5"), "siconos")
    global_file(path("documented_global_triplet.hdf5"), "documented")
    global_file(path("csc_global.hdf5"), "csc")
    global_file(path("bad_global_with_g.hdf5"), "siconos", with_g=True)
    global_file(path("square_global_siconos.hdf5"), "siconos", problem=SQUARE)
    global_file(path("square_global_documented.hdf5"), "documented", problem=SQUARE)

    # One broken rule per file.
    local_file(path("bad_upper_triangle_triplet.hdf5"), upper_triangle_triplet)
    local_file(path("bad_spacedim2.hdf5"), csc_writer, spacedim=2)
    local_file(path("bad_nan_q.hdf5"), csc_writer, q=np.where(np.arange(9) == 4, np.nan, Q))
    # Valid, but scaled beyond what double precision solves (hapco-solve refuses it).
    local_file(path("bad_scale_q_1e160.hdf5"), csc_writer, q=Q * 1e160)
    local_file(path("bad_short_x.hdf5"), short_x_csc)
    local_file(path("bad_mu_size.hdf5"), csc_writer, mu=MU[:2])
    local_file(path("bad_vlen_title.hdf5"), csc_writer, info={})
    with h5py.File(path("bad_vlen_title.hdf5"), "a") as f:  # h5py's default str is vlen
        f["fclib_local/info"].create_dataset("title", data="variable-length title")
    local_file(path("bad_with_vr.hdf5"), csc_writer)
    with h5py.File(path("bad_with_vr.hdf5"), "a") as f:
        for name in ("V", "R"):
            g = f["fclib_local"].create_group(name)
            write_matrix(g, 9 if name == "V" else 1, 1, -1, 1, [0, 1], [0], [1.0])
        doubles(f["fclib_local/vectors"], "s", [0.0])
    with h5py.File(path("bad_global.hdf5"), "w") as f:  # a valid minimal global problem (historical name)
        top = f.create_group("fclib_global")
        int1(top, "spacedim", 3)
        write_matrix(top.create_group("M"), 3, 3, -1, 3, [0, 1, 2, 3], [0, 1, 2], [1.0] * 3)
        write_matrix(top.create_group("H"), 3, 3, -1, 3, [0, 1, 2, 3], [0, 1, 2], [1.0] * 3)
        vec = top.create_group("vectors")
        doubles(vec, "f", [0.0, 0.0, -1.0])
        doubles(vec, "w", [0.0, 0.0, 0.0])
        doubles(vec, "mu", [0.5])
    with h5py.File(path("bad_not_fclib.hdf5"), "w") as f:
        doubles(f.create_group("something_else"), "data", [1.0, 2.0])
    print("wrote FCLIB test files to", out)


if __name__ == "__main__":
    main()
