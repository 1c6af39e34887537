#!/usr/bin/python3
"""Writes a collection of FCLIB problems shaped like the ones OTHER tools write (Siconos,
LMGC90, an iterative-solver based FEM code), for benchmarking hapco-solve against them.

usage: scripts/make_fclib_collection.py OUT_DIR [--quick] [--seed N]

  OUT_DIR     created if needed; gets the .hdf5 files and manifest.csv
  --quick     granular sizes 10, 30, 100 only (default: 10, 30, 100, 300, 1000 spheres)
  --seed N    base seed (default 1); every file is a deterministic function of (seed, file)
  --no-check  skip the read-back checks (they run by default, see "Checks" below)

Needs python3-h5py, numpy, scipy (Debian packages). Single-threaded BLAS is requested so the
files do not depend on the thread count. One line per file is printed; OUT_DIR/manifest.csv has
  file,family,kind,writer_convention,contacts,dofs,max_rel_asymmetry,description
with max_rel_asymmetry = max|A - A^T| / max|A| of the stored W (local) or M (global), and
dofs = the size of v (global), the 6N sphere dofs behind a granular local problem, or the free
dofs of the elastic model.

HDF5 layout (what libfclib's fclib_write_local / fclib_write_global produce; helpers copied
from scripts/make_siconos_style_fclib.py): int32 1-element datasets nzmax, m, n, nz, int32 p and
i, float64 x; triplets store nz entries of p and i and nzmax entries of x (nzmax = nz here);
fixed-length NUL-terminated ASCII strings in info/{title, description, math_info}.
  local  /fclib_local/{spacedim=3, W/..., vectors/{q, mu}, info/...}      u = W r + q
  global /fclib_global/{spacedim=3, M/..., H/..., [G/...], vectors/{f, w, mu, [b]}, info/...}
         M v = H r + G lambda + f,  G^T v + b = 0,  u = H^T v + w   (fclib.h)
Per contact the local coordinates are [normal, t1, t2]; (n, t1, t2) is a right-handed
orthonormal frame, n points from body 2 to body 1 (so u_n > 0 is separation).

Matrix storage conventions written (column writer_convention of the manifest):
  siconos-triplet      nz >= 0, ROWS in `i`, COLUMNS in `p` (CSparse triplets via NM_triplet:
                       what Siconos writes for global M and H), entries in column-major order,
                       nzmax = nz
  fclib.h-triplet      nz >= 0, rows in `p`, columns in `i` (what fclib.h documents), row-major
  csc                  nz = -1, p = n+1 column pointers, i = row indices
  csr-blocks           nz = -2, compressed rows of the non-zero 3x3 blocks of W, zeros inside a
                       stored block kept (Siconos SBM_to_sparse / LMGC90-like block assembly)
  csr-dense            nz = -2, every entry stored (Siconos NM_DENSE)

Families (SI units throughout: m, kg, s, N):
 granular  (global, siconos-triplet) N rigid spheres, radius U[0.8, 1.2] cm, glass density
           2500 kg/m^3, poured in a square box (side 2 R_mean max(3, round(N^(1/3))), walls x = 0, L and
           y = 0, L, ground z = 0): started one per cell of a loose cubic lattice, settled by a
           frictionless penalty relaxation under gravity (FIRE, contact stiffness raised from
           1e3 to 5e4 N/m, so the final overlaps are ~1e-5 m), then a N(0, 1e-5 m) jitter of
           the centres: small gaps and overlaps. Contacts: sphere-sphere,
           sphere-ground and sphere-wall for gaps below the detection distance 2e-4 m. 6 dofs per
           sphere, v = [translation velocity (m/s), angular velocity (rad/s, world frame)];
           M = blockdiag(m I3, (2/5) m R^2 I3). One Moreau-Jean step, h = 1e-3 s, theta = 1:
             f = M v_prev + h f_ext (kg m/s; f_ext = gravity, g = 9.81 m/s^2 along -z),
             v_prev ~ N(0, 5e-3 m/s) per translation component, N(0, 0.5 rad/s) per rotation,
             w = [max(gap, 0) / h, 0, 0] per contact (m/s): an open contact (gap > 0) may close
             within the step but not penetrate; an overlapping one only may not penetrate
             further (no position correction), r = impulses (N s), u = velocities (m/s).
           H column (3 alpha + k), frame vector e_k of contact alpha: sphere 1 rows get
           [e_k ; r1 x e_k] with lever arm r1 = -R1 n, sphere 2 rows get -[e_k ; r2 x e_k] with
           r2 = +R2 n (walls/ground are fixed: no rows), so (H^T v)_(3 alpha + k) =
           e_k . ((v1 + om1 x r1) - (v2 + om2 x r2)), the relative velocity of the contact points
           (om = angular velocity).
           mu = 0.3, or per contact U[0.1, 0.8] in the files whose description says "mixed mu".
 granular  (local, csr-blocks) the same problems condensed: W = H^T M^-1 H (s/kg),
           q = H^T M^-1 f + w (m/s). Assembled block by block like LMGC90: W_ab for a <= b as
           sum_k H_a[k]^T (M_kk^-1 H_b[k]) over the shared dofs k in increasing order, for a > b
           as sum_k (M_kk^-1 H_a[k])^T H_b[k] in decreasing order: W is symmetric only up to
           round-off (~5e-17 relative, measured and reported).
 elastic   (local, siconos-triplet or csr-dense) quasi-static contact of an elastic block
           against a rigid plane: a nx x ny x nz grid of nodes, spacing 5 mm, springs along the
           edges (5e3 N/m), face diagonals (2.5e3 N/m) and body diagonals (1.25e3 N/m) (a soft,
           rubber-like block, E ~ 1 MPa), bottom layer clamped; contacts at the top-face nodes;
           the plane is pushed down by 0.1 mm onto a rough surface (initial gaps U[0, 0.15] mm)
           and slid by (30, 10) um; W = C K^-1 C^T (m/N) computed column by column with scipy's
           CG (relative residual 1e-7, no preconditioner), so W_ij and W_ji differ at the CG
           accuracy: max|W - W^T| / max|W| ~ 2e-8, and up to ~1e-5 relative to the entry itself
           for the small entries (>= 1e-3 max|W|) between distant contacts (both reported in the
           description); q = [g0 - indentation, -t1.s, -t2.s] (m),
           r = forces (N), u = displacements (m). mu 0.3, 0.6 or mixed U[0.1, 0.8].
 layout    global granular problems in the other layouts: M and H as csc; M and H as
           fclib.h-triplet with a rectangular H (n != 3 nc, and the column indices reach past n,
           so reading `i` as rows is out of range: the conventions can be told apart); one
           problem with an equality constraint G (n x 3, siconos-triplet) and b that drives
           sphere 0 at a prescribed velocity: G^T v + b = 0 with G selecting sphere 0's
           translation and b = -v_drive (a reader may refuse G).

Checks (always, unless --no-check): every file is read back with h5py and rebuilt with the
convention it was written in: index ranges and pointer arrays valid, vector sizes, mu >= 0, M
exactly symmetric and positive definite, M and H equal to the in-memory ones; for the
granular problems the contact frames are orthonormal and H^T v equals the relative contact-point
velocity computed directly, and each local W (and q) is recomputed from the stored global file
(H^T M^-1 H) and must agree to 1e-12 relative; the elastic W is compared with a direct sparse
solve; the fclib.h-triplet file must be out of range under the Siconos reading.
"""
import argparse
import csv
import os
import sys
import time

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import h5py  # noqa: E402
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
import scipy.sparse.linalg as spla  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fclib_h5 import doubles, fixed_string, int1, ints, write_matrix  # noqa: E402,F401

GRAVITY = 9.81  # m/s^2
DENSITY = 2500.0  # kg/m^3 (glass)
TIME_STEP = 1e-3  # s
RADIUS_RANGE = (0.008, 0.012)  # m
DETECTION = 2e-4  # m: contact detected when gap < DETECTION
# (penalty stiffness N/m, max FIRE steps) of the packing relaxation: soft first (fast
# settling), then stiff (overlaps ~1e-5 m)
RELAX_SCHEDULE = ((1e3, 2500), (1e4, 1000), (5e4, 1500))
JITTER = 1e-5  # m
MU_DEFAULT = 0.3

# ----------------------------------------------------------------------------- HDF5 helpers
# fclib_h5 (this directory): the layout libfclib writes.


def write_info(top, title, description, math_info, ndof=None):
    g = top.create_group("info")
    fixed_string(g, "title", title)
    fixed_string(g, "description", description)
    fixed_string(g, "math_info", math_info)
    if ndof is not None:  # Siconos adds this attribute
        g.attrs.create("numberOfDegreeOfFreedom", ndof, dtype="<i4")


# ------------------------------------------------------------------- matrix storage writers


def store(group, a, convention):
    """Writes the scipy sparse matrix `a` (explicit zeros kept) in `convention`."""
    m, n = a.shape
    if convention == "siconos-triplet":
        c = sp.csc_matrix(a)
        c.has_sorted_indices = False
        c.sort_indices()
        cols = np.repeat(np.arange(n), np.diff(c.indptr))
        write_matrix(group, m, n, c.nnz, c.nnz, cols, c.indices, c.data)  # p = cols, i = rows
    elif convention == "fclib.h-triplet":
        r = sp.csr_matrix(a)
        r.sort_indices()
        rows = np.repeat(np.arange(m), np.diff(r.indptr))
        write_matrix(group, m, n, r.nnz, r.nnz, rows, r.indices, r.data)  # p = rows, i = cols
    elif convention == "csc":
        c = sp.csc_matrix(a)
        c.sort_indices()
        write_matrix(group, m, n, -1, c.nnz, c.indptr, c.indices, c.data)
    elif convention in ("csr-blocks", "csr-dense"):
        r = sp.csr_matrix(a)
        r.sort_indices()
        write_matrix(group, m, n, -2, r.nnz, r.indptr, r.indices, r.data)
    else:
        raise ValueError(convention)


def load(group, convention):
    """Reads a matrix group back with `convention`, checking the arrays; returns csr."""
    g = {k: group[k][()] for k in ("nzmax", "m", "n", "nz", "p", "i", "x")}
    nzmax, m, n, nz = (int(g[k][0]) for k in ("nzmax", "m", "n", "nz"))
    p, i, x = g["p"].astype(np.int64), g["i"].astype(np.int64), g["x"]
    for k in ("nzmax", "m", "n", "nz", "p", "i"):
        assert group[k].dtype == np.dtype("<i4"), (group.name, k, group[k].dtype)
    assert x.dtype == np.dtype("<f8") and np.all(np.isfinite(x)), group.name
    assert len(x) == nzmax and m > 0 and n > 0, group.name
    if convention.endswith("triplet"):
        assert nz >= 0 and nz <= nzmax and len(p) == nz and len(i) == nz, group.name
        rows, cols = (i, p) if convention == "siconos-triplet" else (p, i)
        assert rows.min() >= 0 and rows.max() < m and cols.min() >= 0 and cols.max() < n, \
            (group.name, "triplet index out of range for " + convention)
        return sp.csr_matrix((x[:nz], (rows, cols)), shape=(m, n))
    outer = n if convention == "csc" else m
    inner = m if convention == "csc" else n
    assert nz == (-1 if convention == "csc" else -2), group.name
    assert len(p) == outer + 1 and p[0] == 0 and p[-1] == nzmax and np.all(np.diff(p) >= 0)
    assert len(i) == nzmax and (nzmax == 0 or (i.min() >= 0 and i.max() < inner)), group.name
    for k in range(outer):  # no duplicate inner index within a column/row
        seg = i[p[k]:p[k + 1]]
        assert len(np.unique(seg)) == len(seg), (group.name, "duplicate index")
    if convention == "csc":
        return sp.csc_matrix((x, i, p), shape=(m, n)).tocsr()
    return sp.csr_matrix((x, i, p), shape=(m, n))


def rel_asymmetry(a):
    a = sp.csr_matrix(a)
    d = abs(a - a.T)
    scale = abs(a).max()
    return float(d.max() / scale) if d.nnz else 0.0


def entry_asymmetry(a):
    """max |A_ij - A_ji| / |A_ij| over the entries with |A_ij| >= 1e-3 max|A| (dense A)."""
    big = np.abs(a) >= 1e-3 * np.abs(a).max()
    return float(np.max(np.abs(a - a.T)[big] / np.abs(a)[big]))


# ------------------------------------------------------------------------- contact frames


def frames(normals):
    """(nc, 3, 3): rows n, t1, t2, right-handed orthonormal, t1 normal to the axis of n's
    smallest component."""
    n = normals / np.linalg.norm(normals, axis=1)[:, None]
    axis = np.zeros_like(n)
    axis[np.arange(len(n)), np.argmin(np.abs(n), axis=1)] = 1.0
    t1 = np.cross(n, axis)
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    t2 = np.cross(n, t1)
    return np.stack([n, t1, t2], axis=1)


# -------------------------------------------------------------------------- granular scene


def box_side(count):
    return 2.0 * np.mean(RADIUS_RANGE) * max(3.0, round(count ** (1.0 / 3.0)))


def wall_overlaps(x, radius, side):
    """Per sphere and plane (ground, x=0, x=L, y=0, y=L): gap and inward normal."""
    gaps = np.stack([x[:, 2] - radius, x[:, 0] - radius, side - x[:, 0] - radius,
                     x[:, 1] - radius, side - x[:, 1] - radius], axis=1)
    normals = np.array([[0, 0, 1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]], float)
    return gaps, normals


def loose_lattice(radius, side, rng):
    """Initial positions: one sphere per cell of a cubic lattice (cell 2.04 R_max) filled
    layer by layer from the ground, at a random place inside its cell."""
    cell = 2.0 * radius.max() * 1.02
    per_row = int(side // cell)
    margin = 0.5 * (side - per_row * cell)
    x = np.zeros((len(radius), 3))
    for s, rs in enumerate(radius):
        layer, k = divmod(s, per_row * per_row)
        ix, iy = divmod(k, per_row)
        corner = margin + cell * np.array([ix, iy])
        x[s, :2] = corner + rs + rng.uniform(0.0, cell - 2 * rs, size=2)
        x[s, 2] = radius.max() + layer * cell + rng.uniform(0.0, 0.02 * cell)
    return x


def relax(x, radius, mass, side, k, max_steps):
    """FIRE minimisation (Bitzek et al. 2006) of gravity + penalty overlap energy (stiffness k,
    no friction): the spheres settle into a random packing. Returns positions, steps."""
    count = len(radius)
    weight = np.zeros((count, 3))
    weight[:, 2] = -mass * GRAVITY
    base = np.sqrt(mass.min() / k)
    dt, dt_max, alpha, positive = 0.05 * base, 0.3 * base, 0.1, 0
    v = np.zeros_like(x)
    skin = 0.25 * radius.min()
    pairs, anchor = None, None
    _, normals = wall_overlaps(x, radius, side)
    step = 0
    for step in range(max_steps):
        if pairs is None or np.max(np.linalg.norm(x - anchor, axis=1)) > 0.5 * skin:
            pairs = cKDTree(x).query_pairs(2 * radius.max() + skin, output_type="ndarray")
            anchor = x.copy()
        force = weight.copy()
        if len(pairs):
            a, b = pairs[:, 0], pairs[:, 1]
            d = x[a] - x[b]
            dist = np.linalg.norm(d, axis=1)
            push = k * np.maximum(radius[a] + radius[b] - dist, 0.0) / dist
            fab = d * push[:, None]
            for c in range(3):
                force[:, c] += (np.bincount(a, fab[:, c], count)
                                - np.bincount(b, fab[:, c], count))
        gaps, _ = wall_overlaps(x, radius, side)
        force += (k * np.maximum(-gaps, 0.0)) @ normals
        if np.max(np.linalg.norm(force, axis=1) / (mass * GRAVITY)) < 1e-3:
            break
        power = np.sum(force * v)
        if power > 0:
            fn = np.linalg.norm(force)
            v = (1 - alpha) * v + alpha * np.linalg.norm(v) * force / fn
            positive += 1
            if positive > 5:
                dt, alpha = min(1.1 * dt, dt_max), 0.99 * alpha
        else:
            dt, alpha, positive = 0.5 * dt, 0.1, 0
            v[:] = 0.0
        v += dt * force / mass[:, None]
        x = x + dt * v
    return x, step + 1


def granular_scene(count, rng):
    radius = rng.uniform(*RADIUS_RANGE, size=count)
    mass = DENSITY * 4.0 / 3.0 * np.pi * radius ** 3
    side = box_side(count)
    x = loose_lattice(radius, side, rng)
    steps = 0
    for k, max_steps in RELAX_SCHEDULE:
        x, done = relax(x, radius, mass, side, k, max_steps)
        steps += done
    x = x + rng.normal(0.0, JITTER, size=x.shape)
    # contacts: body1, body2 (-1 = fixed ground/wall), normal (2 -> 1), gap, kind
    b1, b2, normal, gap, kind = [], [], [], [], []
    pairs = cKDTree(x).query_pairs(2 * radius.max() + DETECTION, output_type="ndarray")
    if len(pairs):
        pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
    for i, j in pairs:
        d = x[i] - x[j]
        dist = np.linalg.norm(d)
        g = dist - radius[i] - radius[j]
        if g < DETECTION:
            b1.append(i), b2.append(j), normal.append(d / dist), gap.append(g), kind.append(0)
    gaps, normals = wall_overlaps(x, radius, side)
    for s in range(count):
        for w in range(5):
            if gaps[s, w] < DETECTION:
                b1.append(s), b2.append(-1), normal.append(normals[w]), gap.append(gaps[s, w])
                kind.append(1 if w == 0 else 2)
    return dict(radius=radius, mass=mass, x=x, side=side, relax_steps=steps,
                b1=np.array(b1, int), b2=np.array(b2, int), normal=np.array(normal),
                gap=np.array(gap), kind=np.array(kind))


def granular_problem(scene, rng, mixed_mu):
    """Global problem of one Moreau-Jean step: M (diag), H (csc), f, w, mu + the H blocks."""
    radius, mass = scene["radius"], scene["mass"]
    count, nc = len(radius), len(scene["b1"])
    ndof = 6 * count
    mdiag = np.stack([mass] * 3 + [0.4 * mass * radius ** 2] * 3, axis=1).reshape(-1)
    frame = frames(scene["normal"])  # (nc, 3 directions, 3 components)
    b1, b2 = scene["b1"], scene["b2"]
    lever1 = -radius[b1][:, None] * frame[:, 0]
    lever2 = np.where((b2 >= 0)[:, None], radius[np.maximum(b2, 0)][:, None] * frame[:, 0], 0.0)
    # blocks[side][alpha] is 6 x 3: rows = dofs of that body, column k = direction e_k
    blk1 = np.concatenate([frame, np.cross(lever1[:, None, :], frame)], axis=2)
    blk2 = -np.concatenate([frame, np.cross(lever2[:, None, :], frame)], axis=2)
    blk1, blk2 = blk1.transpose(0, 2, 1), blk2.transpose(0, 2, 1)  # (nc, 6, 3)
    rows, cols, vals = [], [], []
    for side, body, blk in ((1, b1, blk1), (2, b2, blk2)):
        keep = body >= 0
        alpha = np.nonzero(keep)[0]
        r = (6 * body[keep])[:, None, None] + np.arange(6)[None, :, None]
        c = (3 * alpha)[:, None, None] + np.arange(3)[None, None, :]
        rows.append(np.broadcast_to(r, (len(alpha), 6, 3)).ravel())
        cols.append(np.broadcast_to(c, (len(alpha), 6, 3)).ravel())
        vals.append(blk[keep].ravel())
    H = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(ndof, 3 * nc))
    H.eliminate_zeros()  # exact zeros: normal rows have no rotational part (r x n = 0)
    H.sort_indices()
    M = sp.csc_matrix(sp.diags(mdiag))
    v_prev = np.concatenate([rng.normal(0.0, 5e-3, (count, 3)),
                             rng.normal(0.0, 0.5, (count, 3))], axis=1).reshape(-1)
    f_ext = np.zeros((count, 6))
    f_ext[:, 2] = -mass * GRAVITY
    f = mdiag * v_prev + TIME_STEP * f_ext.reshape(-1)
    w = np.zeros(3 * nc)
    w[0::3] = np.maximum(scene["gap"], 0.0) / TIME_STEP
    mu = rng.uniform(0.1, 0.8, nc) if mixed_mu else np.full(nc, MU_DEFAULT)
    return dict(M=M, mdiag=mdiag, H=H, f=f, w=w, mu=mu, frame=frame, lever1=lever1,
                lever2=lever2, blk1=blk1, blk2=blk2, ndof=ndof, nc=nc)


def check_kinematics(scene, prob, rng):
    """H^T v against the relative velocity of the contact points, computed directly."""
    fr = prob["frame"]
    assert np.allclose(np.einsum("aij,akj->aik", fr, fr), np.eye(3)[None], atol=1e-14)
    assert np.allclose(np.linalg.det(fr), 1.0)
    v = rng.normal(size=(len(scene["radius"]), 6))
    b1, b2 = scene["b1"], scene["b2"]
    vel1 = v[b1, :3] + np.cross(v[b1, 3:], prob["lever1"])
    vel2 = np.where((b2 >= 0)[:, None],
                    v[np.maximum(b2, 0), :3] + np.cross(v[np.maximum(b2, 0), 3:], prob["lever2"]),
                    0.0)
    direct = np.einsum("akj,aj->ak", fr, vel1 - vel2).reshape(-1)
    err = np.max(np.abs(prob["H"].T @ v.reshape(-1) - direct))
    assert err < 1e-12 * max(1.0, np.max(np.abs(direct))), err


def lmgc_style_w(scene, prob):
    """W = H^T M^-1 H assembled by 3x3 blocks; a < b and a > b in different orders."""
    b1, b2 = scene["b1"], scene["b2"]
    nc = prob["nc"]
    inv = 1.0 / prob["mdiag"]
    # (contact, side, body) for every moving body of every contact
    ca = np.concatenate([np.arange(nc), np.nonzero(b2 >= 0)[0]])
    side = np.concatenate([np.ones(nc, int), np.full(np.sum(b2 >= 0), 2)])
    body = np.concatenate([b1, b2[b2 >= 0]])
    order = np.lexsort((ca, body))
    ca, side, body = ca[order], side[order], body[order]
    blk = {1: prob["blk1"], 2: prob["blk2"]}
    # all (a, b) pairs sharing a body, both orders, including a == b
    starts = np.r_[0, np.nonzero(np.diff(body))[0] + 1, len(body)]
    A, SA, B, SB, BODY = [], [], [], [], []
    for s0, s1 in zip(starts[:-1], starts[1:]):
        idx = np.arange(s0, s1)
        ia, ib = np.meshgrid(idx, idx, indexing="ij")
        A.append(ca[ia.ravel()]), SA.append(side[ia.ravel()])
        B.append(ca[ib.ravel()]), SB.append(side[ib.ravel()]), BODY.append(body[ia.ravel()])
    A, SA, B, SB, BODY = map(np.concatenate, (A, SA, B, SB, BODY))
    HA = np.where((SA == 1)[:, None, None], blk[1][A], blk[2][A])  # (npair, 6, 3)
    HB = np.where((SB == 1)[:, None, None], blk[1][B], blk[2][B])
    minv = inv[(6 * BODY)[:, None] + np.arange(6)[None, :]]  # (npair, 6)
    upper = A <= B
    acc = np.zeros((len(A), 3, 3))
    for k in range(6):  # a <= b: H_a^T (M^-1 H_b), dofs in increasing order
        acc[upper] += HA[upper, k, :, None] * (HB[upper, k, None, :] * minv[upper, k, None, None])
    for k in reversed(range(6)):  # a > b: (M^-1 H_a)^T H_b, dofs in decreasing order
        low = ~upper
        acc[low] += (HA[low, k, :, None] * minv[low, k, None, None]) * HB[low, k, None, :]
    # sum the (at most two: a == b) body contributions per block, in body order
    key = A * nc + B
    order = np.argsort(key, kind="stable")
    key, acc = key[order], acc[order]
    uniq, first = np.unique(key, return_index=True)
    summed = np.add.reduceat(acc, first, axis=0)
    # block CSR -> scalar CSR keeping every entry of a stored block
    ba = (uniq // nc).astype(int)
    bb = (uniq % nc).astype(int)
    bsr = sp.bsr_matrix((summed, bb, np.r_[0, np.cumsum(np.bincount(ba, minlength=nc))]),
                        shape=(3 * nc, 3 * nc), blocksize=(3, 3))
    coo = bsr.tocoo()  # keeps explicit zeros of stored blocks
    W = sp.csr_matrix((coo.data, (coo.row, coo.col)), shape=(3 * nc, 3 * nc))
    W.sort_indices()
    assert W.nnz == 9 * len(uniq), "a stored block lost entries"
    # q = H^T M^-1 f + w, per contact, body 1 then body 2
    mf = prob["f"] * inv
    q = prob["w"].copy()
    for sd, bodies in ((1, b1), (2, b2)):
        keep = bodies >= 0
        vloc = mf[(6 * bodies[keep])[:, None] + np.arange(6)[None, :]]
        q.reshape(-1, 3)[keep] += np.einsum("akj,ak->aj", blk[sd][keep], vloc)
    return W, q


# ------------------------------------------------------------------------- elastic problems


def elastic_problem(nx, ny, nz, rng, mu_mode):
    spacing, k_edge = 5e-3, 5e3
    idx = np.arange(nx * ny * nz).reshape(nx, ny, nz)
    pos = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"),
                   axis=-1).reshape(-1, 3) * spacing
    i_list, j_list, k_list = [], [], []
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, -1, 0), (1, 0, 1), (1, 0, -1),
                (0, 1, 1), (0, 1, -1), (1, 1, 1), (1, 1, -1), (1, -1, 1), (1, -1, -1)]:
        o = np.array(off)
        lo = np.maximum(0, -o)
        hi = np.array([nx, ny, nz]) - np.maximum(0, o)
        a = idx[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]].ravel()
        b = idx[lo[0] + o[0]:hi[0] + o[0], lo[1] + o[1]:hi[1] + o[1],
                lo[2] + o[2]:hi[2] + o[2]].ravel()
        i_list.append(a), j_list.append(b)
        k_list.append(np.full(len(a), k_edge / 2.0 ** (np.sum(np.abs(o)) - 1)))
    a, b, ks = map(np.concatenate, (i_list, j_list, k_list))
    e = pos[b] - pos[a]
    e /= np.linalg.norm(e, axis=1)[:, None]
    kee = ks[:, None, None] * e[:, :, None] * e[:, None, :]
    r3 = np.arange(3)
    rows, cols, vals = [], [], []
    for p_, q_, sgn in ((a, a, 1), (b, b, 1), (a, b, -1), (b, a, -1)):
        rows.append(np.broadcast_to((3 * p_)[:, None, None] + r3[None, :, None], kee.shape).ravel())
        cols.append(np.broadcast_to((3 * q_)[:, None, None] + r3[None, None, :], kee.shape).ravel())
        vals.append(sgn * kee.ravel())
    nn = nx * ny * nz
    K = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(3 * nn, 3 * nn))
    free_nodes = idx[:, :, 1:].ravel()
    free = np.sort((3 * free_nodes[:, None] + r3[None, :]).ravel())
    K = K[free][:, free]
    K = ((K + K.T) * 0.5).tocsr()  # exactly symmetric
    K.sort_indices()
    ndof = K.shape[0]
    top = idx[:, :, nz - 1].ravel()
    nc = len(top)
    where = {dof: k for k, dof in enumerate(free)}
    frame = frames(np.tile([0.0, 0.0, -1.0], (nc, 1)))  # n from the plane (2) to the block (1)
    crow, ccol, cval = [], [], []
    for alpha, node in enumerate(top):
        for kdir in range(3):
            for comp in range(3):
                if frame[alpha, kdir, comp] != 0.0:
                    crow.append(3 * alpha + kdir)
                    ccol.append(where[3 * node + comp])
                    cval.append(frame[alpha, kdir, comp])
    C = sp.csr_matrix((cval, (crow, ccol)), shape=(3 * nc, ndof))
    # column by column with CG, as an iterative-solver based code does
    W = np.zeros((3 * nc, 3 * nc))
    iters = []
    CT = C.T.tocsc()
    for j in range(3 * nc):
        rhs = CT[:, j].toarray().ravel()
        count = [0]

        def cb(_xk, count=count):
            count[0] += 1
        xj, info = spla.cg(K, rhs, tol=1e-7, atol=0.0, maxiter=20 * ndof, callback=cb)
        assert info == 0, ("CG did not converge", j, info)
        iters.append(count[0])
        W[:, j] = C @ xj
    indentation, rough = 1e-4, 1.5e-4
    slide = np.array([3e-5, 1e-5, 0.0])
    g0 = rng.uniform(0.0, rough, nc)
    q = np.zeros(3 * nc)
    q[0::3] = g0 - indentation
    q[1::3] = -frame[:, 1] @ slide
    q[2::3] = -frame[:, 2] @ slide
    if mu_mode == "mixed":
        mu = rng.uniform(0.1, 0.8, nc)
    else:
        mu = np.full(nc, float(mu_mode))
    return dict(K=K, C=C, W=W, q=q, mu=mu, nc=nc, ndof=ndof, cg_iters=iters,
                penetrating=int(np.sum(q[0::3] < 0)))


# ---------------------------------------------------------------------------------- writers


def write_global(path, prob, conv_m, conv_h, title, description, math_info, G=None, b=None,
                 conv_g="siconos-triplet"):
    with h5py.File(path, "w") as f:
        top = f.create_group("fclib_global")
        int1(top, "spacedim", 3)
        store(top.create_group("M"), prob["M"], conv_m)
        store(top.create_group("H"), prob["H"], conv_h)
        if G is not None:
            store(top.create_group("G"), G, conv_g)
        vec = top.create_group("vectors")
        doubles(vec, "f", prob["f"])
        doubles(vec, "w", prob["w"])
        doubles(vec, "mu", prob["mu"])
        if G is not None:
            doubles(vec, "b", b)
        write_info(top, title, description, math_info)


def write_local(path, W, q, mu, conv, title, description, math_info, ndof):
    with h5py.File(path, "w") as f:
        top = f.create_group("fclib_local")
        int1(top, "spacedim", 3)
        store(top.create_group("W"), W, conv)
        vec = top.create_group("vectors")
        doubles(vec, "q", q)
        doubles(vec, "mu", mu)
        write_info(top, title, description, math_info, ndof=ndof)


def read_info(top):
    out = {}
    for k in ("title", "description", "math_info"):
        d = top["info"][k]
        assert d.dtype.kind == "S" and h5py.check_string_dtype(d.dtype) is not None
        raw = d[()]
        out[k] = raw.decode("ascii")
        assert d.id.get_type().get_strpad() == h5py.h5t.STR_NULLTERM
    assert out["title"] and out["description"], "info must say what the problem is"
    return out


def check_global(path, conv_m, conv_h, prob, G=None, b=None, conv_g="siconos-triplet"):
    with h5py.File(path, "r") as f:
        top = f["fclib_global"]
        assert int(top["spacedim"][0]) == 3
        M = load(top["M"], conv_m)
        H = load(top["H"], conv_h)
        n, m3 = H.shape
        assert M.shape == (n, n) and m3 % 3 == 0
        assert abs(M - prob["M"]).max() == 0.0, "stored M differs"
        assert abs(H - prob["H"]).max() == 0.0, "stored H differs"
        assert (M != M.T).nnz == 0, "M not exactly symmetric"
        off = M - sp.diags(M.diagonal())
        if off.nnz == 0 or abs(off).max() == 0.0:
            assert np.all(M.diagonal() > 0), "M not positive definite"
        else:
            np.linalg.cholesky(M.toarray())
        vec = top["vectors"]
        fv, w, mu = vec["f"][()], vec["w"][()], vec["mu"][()]
        assert fv.shape == (n,) and w.shape == (m3,) and mu.shape == (m3 // 3,)
        assert np.all(mu >= 0) and np.all(np.isfinite(fv)) and np.all(np.isfinite(w))
        assert np.array_equal(fv, prob["f"]) and np.array_equal(w, prob["w"])
        if G is not None:
            Gs = load(top["G"], conv_g)
            assert Gs.shape[0] == n and abs(Gs - G).max() == 0.0
            assert vec["b"].shape == (Gs.shape[1],) and np.array_equal(vec["b"][()], b)
        else:
            assert "G" not in top and "b" not in vec
        if conv_h == "fclib.h-triplet":  # the Siconos reading must be out of range
            g = top["H"]
            assert (g["i"][()].max() >= int(g["m"][0]) or g["p"][()].max() >= int(g["n"][0])), \
                "conventions not distinguishable by index ranges"
        read_info(top)
    return M, H, fv, w


def check_local(path, conv, W_ref, q_ref, mu_ref, tol):
    with h5py.File(path, "r") as f:
        top = f["fclib_local"]
        assert int(top["spacedim"][0]) == 3
        W = load(top["W"], conv)
        m = W.shape[0]
        assert W.shape == (m, m) and m % 3 == 0
        q, mu = top["vectors"]["q"][()], top["vectors"]["mu"][()]
        assert q.shape == (m,) and mu.shape == (m // 3,) and np.all(mu >= 0)
        assert np.array_equal(mu, mu_ref)
        ref = sp.csr_matrix(W_ref)
        scale = abs(ref).max()
        err_w = abs(W - ref).max() / scale
        err_q = np.max(np.abs(q - q_ref)) / max(np.max(np.abs(q_ref)), 1e-300)
        assert err_w <= tol and err_q <= tol, (path, err_w, err_q)
        read_info(top)
    return W, err_w


# ------------------------------------------------------------------------------------ main


def describe_scene(scene):
    kinds = np.bincount(scene["kind"], minlength=3)
    g = scene["gap"]
    return ("%d spheres (R in [0.8,1.2] cm, 2500 kg/m^3) in a %.1f cm square box; %d contacts:"
            " %d sphere-sphere, %d sphere-ground, %d sphere-wall; gaps %.1e .. %.1e m (%d "
            "overlapping, detection distance %.0e m)" % (
                len(scene["radius"]), 100 * scene["side"], len(g), kinds[0], kinds[1], kinds[2],
                g.min(), g.max(), int(np.sum(g < 0)), DETECTION))


GRANULAR_UNITS = ("Moreau-Jean step h=1e-3 s: M v = H r + f, u = H^T v + w; f = M v_prev + "
                  "h*gravity (kg m/s), w_n = max(gap,0)/h (m/s), r impulses (N s), v = per sphere"
                  " [velocity m/s, angular velocity rad/s (world)], SI units; contact frame "
                  "[n,t1,t2], n from body 2 to body 1 (walls/ground are body 2)")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out_dir")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-check", action="store_true")
    args = ap.parse_args()
    check = not args.no_check
    os.makedirs(args.out_dir, exist_ok=True)
    rows = []
    t_start = time.process_time()

    def rng_for(*key):
        return np.random.default_rng([args.seed] + [int(k) for k in key])

    def emit(name, family, kind, conv, nc, ndof, asym, desc):
        path = os.path.join(args.out_dir, name)
        size = os.path.getsize(path)
        rows.append(dict(file=name, family=family, kind=kind, writer_convention=conv,
                         contacts=nc, dofs=ndof, max_rel_asymmetry="%.3e" % asym,
                         description=desc))
        print("%-44s %-8s %-6s %-16s contacts %5d dofs %5d asym %.2e %8.1f kB" % (
            name, family, kind, conv, nc, ndof, asym, size / 1024.0), flush=True)

    # a) + b): granular global (Siconos) and local (LMGC90-like)
    sizes = [10, 30, 100] if args.quick else [10, 30, 100, 300, 1000]
    for s_index, count in enumerate(sizes):
        rng = rng_for(1, count)
        scene = granular_scene(count, rng)
        mixed = count in (30, 300)
        prob = granular_problem(scene, rng, mixed)
        if check:
            check_kinematics(scene, prob, rng_for(99, count))
        mu_text = "mixed mu U[0.1,0.8] per contact" if mixed else "mu = 0.3"
        desc = describe_scene(scene) + "; " + mu_text + "; " + GRANULAR_UNITS
        gname = "granular_N%04d_global_siconos.hdf5" % count
        write_global(os.path.join(args.out_dir, gname), prob, "siconos-triplet",
                     "siconos-triplet",
                     "granular: %d spheres poured in a box, global problem, Siconos-style "
                     "triplets (rows in i, columns in p)" % count,
                     desc + ". Written as Siconos does: M and H as CSparse triplets, rows in i,"
                     " columns in p, nzmax = nz (fclib.h documents the opposite).",
                     "M symmetric positive definite, block diagonal (m I3, 2/5 m R^2 I3); "
                     "H %d x %d" % prob["H"].shape)
        asym_m = rel_asymmetry(prob["M"])
        if check:
            Ms, Hs, fs, ws = check_global(os.path.join(args.out_dir, gname), "siconos-triplet",
                                          "siconos-triplet", prob)
        emit(gname, "granular", "global", "siconos-triplet", prob["nc"], prob["ndof"], asym_m,
             describe_scene(scene) + "; " + mu_text)

        W, q = lmgc_style_w(scene, prob)
        asym = rel_asymmetry(W)
        lname = "granular_N%04d_local_blockcsr.hdf5" % count
        write_local(os.path.join(args.out_dir, lname), W, q, prob["mu"], "csr-blocks",
                    "granular: %d spheres poured in a box, local problem W = H^T M^-1 H, "
                    "LMGC90-like block assembly, compressed rows of 3x3 blocks" % count,
                    desc + ". Condensed: W = H^T M^-1 H (s/kg), q = H^T M^-1 f + w (m/s), u = W r"
                    " + q; W assembled by 3x3 blocks, W_ab (a<b) and W_ab (a>b) summed in "
                    "different floating-point orders: symmetric up to round-off, measured "
                    "max|W-W^T|/max|W| = %.2e; same problem as %s." % (asym, gname),
                    "W symmetric positive semidefinite up to round-off (rank <= 6N = %d, W is "
                    "%d x %d)" % (prob["ndof"], W.shape[0], W.shape[1]), prob["ndof"])
        if check:
            # W and q recomputed from the STORED global problem
            minv = sp.diags(1.0 / Ms.diagonal())
            W_ref = (Hs.T @ minv @ Hs).tocsr()
            q_ref = Hs.T @ (fs / Ms.diagonal()) + ws
            check_local(os.path.join(args.out_dir, lname), "csr-blocks", W_ref, q_ref,
                        prob["mu"], 1e-12)
        emit(lname, "granular", "local", "csr-blocks", prob["nc"], prob["ndof"], asym,
             "same problem as %s condensed (W = H^T M^-1 H, q = H^T M^-1 f + w), 3x3-block CSR"
             % gname)

    # c) elastic block, W by CG column by column
    for grid, conv, mu_mode in (((5, 5, 4), "siconos-triplet", "0.3"),
                                ((8, 8, 5), "csr-dense", "0.6"),
                                ((12, 12, 6), "siconos-triplet", "mixed")):
        rng = rng_for(3, *grid)
        t0 = time.process_time()
        el = elastic_problem(*grid, rng, mu_mode)
        t_cg = time.process_time() - t0
        W = sp.csr_matrix(el["W"])
        asym = rel_asymmetry(el["W"])
        tag = "%dx%dx%d" % grid
        name = "elastic_%s_local_cg_%s.hdf5" % (tag, "triplet" if conv.endswith("triplet")
                                                  else "csr")
        mu_text = "mixed mu U[0.1,0.8] per contact" if mu_mode == "mixed" else "mu = " + mu_mode
        desc = ("elastic block %s nodes (spacing 5 mm, springs 5e3/2.5e3/1.25e3 N/m along edges/"
                "face/body diagonals, bottom layer clamped, %d free dofs) pressed 0.1 mm onto a "
                "rigid plane and slid (30,10) um; %d contacts at the top-face nodes (initial gaps"
                " U[0,0.15] mm, %d penetrating), %s. Quasi-static: u = W r + q, W = C K^-1 C^T "
                "(m/N) column by column with scipy CG (relative residual 1e-7, %d..%d "
                "iterations), q (m), r forces (N); contact frame [n,t1,t2], n = -z from the "
                "plane to the block. W is symmetric only to the CG accuracy: max|W-W^T|/max|W| "
                "= %.2e, max |W_ij-W_ji|/|W_ij| over entries >= 1e-3 max|W| = %.2e" % (
                    tag, el["ndof"], el["nc"], el["penetrating"], mu_text, min(el["cg_iters"]),
                    max(el["cg_iters"]), asym, entry_asymmetry(el["W"])))
        write_local(os.path.join(args.out_dir, name), W, el["q"], el["mu"], conv,
                    "elastic: %s spring-lattice block against a rigid plane, local problem, W "
                    "from CG solves (symmetric only to the CG accuracy)" % tag,
                    desc + "; stored as %s." % conv,
                    "exact W = C K^-1 C^T symmetric positive definite; the stored W is a CG "
                    "approximation, symmetric only to ~CG tolerance", el["ndof"])
        summary = desc.split(". Quasi-static")[0] + "; W from CG (rtol 1e-7): " + \
            desc.split("accuracy: ")[1]
        if check:
            lu = spla.splu(el["K"].tocsc())
            exact = el["C"] @ lu.solve(el["C"].T.toarray())
            assert rel_asymmetry(exact) < 1e-12
            _, err = check_local(os.path.join(args.out_dir, name), conv, exact, el["q"], el["mu"],
                                 1e-4)
            summary += "; max|W - W_exact|/max|W| = %.2e (direct solve)" % err
        emit(name, "elastic", "local", conv, el["nc"], el["ndof"], asym, summary)
        print("    (CG %.1f s CPU)" % t_cg)

    # d) other layouts (global granular problems)
    for label, count, conv in (("csc", 30, "csc"), ("documented_triplet", 40, "fclib.h-triplet")):
        rng = rng_for(4, count)
        scene = granular_scene(count, rng)
        prob = granular_problem(scene, rng, mixed_mu=False)
        assert prob["ndof"] != 3 * prob["nc"], "H must be rectangular"
        name = "layout_%s_global_N%04d.hdf5" % (label, count)
        desc = describe_scene(scene) + "; mu = 0.3; " + GRANULAR_UNITS
        explain = {"csc": "M and H as compressed columns (nz = -1)",
                   "fclib.h-triplet": "M and H as triplets in the convention fclib.h documents "
                                      "(rows in p, columns in i, nzmax = nz), NOT the Siconos "
                                      "one; H is rectangular (%d x %d): reading i as rows runs "
                                      "out of range" % prob["H"].shape}[conv]
        write_global(os.path.join(args.out_dir, name), prob, conv, conv,
                     "layout test: granular %d spheres, global problem, %s" % (count, explain),
                     desc + ". " + explain + ".",
                     "M symmetric positive definite, block diagonal; H %d x %d" % prob["H"].shape)
        if check:
            check_global(os.path.join(args.out_dir, name), conv, conv, prob)
            if conv == "fclib.h-triplet":
                with h5py.File(os.path.join(args.out_dir, name), "r") as f:
                    try:
                        load(f["fclib_global/H"], "siconos-triplet")
                        raise AssertionError("Siconos reading of a fclib.h triplet succeeded")
                    except AssertionError as e:
                        assert "out of range" in str(e), e
        emit(name, "layout", "global", conv, prob["nc"], prob["ndof"], 0.0,
             describe_scene(scene) + "; " + explain)

    count = 10
    rng = rng_for(5, count)
    scene = granular_scene(count, rng)
    prob = granular_problem(scene, rng, mixed_mu=False)
    v_drive = np.array([0.05, 0.0, 0.0])
    G = sp.csc_matrix((np.ones(3), (np.arange(3), np.arange(3))), shape=(prob["ndof"], 3))
    b = -v_drive
    name = "layout_equality_G_global_N%04d.hdf5" % count
    explain = ("equality constraint G^T v + b = 0 (G %d x 3 selects sphere 0's translation, b = "
               "-v_drive, v_drive = (0.05, 0, 0) m/s: sphere 0 is a pusher driven at a prescribed"
               " velocity; lambda = its reaction impulse, N s); M, H, G as Siconos triplets (rows"
               " in i, columns in p)" % prob["ndof"])
    write_global(os.path.join(args.out_dir, name), prob, "siconos-triplet", "siconos-triplet",
                 "layout test: granular %d spheres with a driven sphere (equality constraint G,"
                 " b), global problem" % count,
                 describe_scene(scene) + "; mu = 0.3; " + GRANULAR_UNITS + ". " + explain + ".",
                 "M symmetric positive definite; G full column rank; a reader without "
                 "equality constraints must refuse this file", G=G, b=b)
    if check:
        check_global(os.path.join(args.out_dir, name), "siconos-triplet", "siconos-triplet",
                     prob, G=G, b=b)
    emit(name, "layout", "global", "siconos-triplet", prob["nc"], prob["ndof"], 0.0,
         describe_scene(scene) + "; " + explain)

    with open(os.path.join(args.out_dir, "manifest.csv"), "w", newline="") as fh:
        wr = csv.DictWriter(fh, fieldnames=["file", "family", "kind", "writer_convention",
                                            "contacts", "dofs", "max_rel_asymmetry",
                                            "description"])
        wr.writeheader()
        wr.writerows(rows)
    total = sum(os.path.getsize(os.path.join(args.out_dir, r["file"])) for r in rows)
    print("%d files, %.1f MB, manifest.csv in %s (%s, %.1f s CPU)" % (
        len(rows), total / 2 ** 20, args.out_dir, "checked" if check else "NOT checked",
        time.process_time() - t_start))


if __name__ == "__main__":
    sys.exit(main())
