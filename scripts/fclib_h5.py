"""The HDF5 layout libfclib writes (checked with h5dump against libfclib 3.1), for the Python
scripts that write FCLIB files other tools' way (make_siconos_style_fclib.py,
make_fclib_collection.py): int32 1-element datasets for sizes, float64 data, fixed-length
NUL-terminated ASCII strings for the info text, no timestamps (reproducible files)."""
import h5py
import numpy as np


def int1(group, name, value):
    group.create_dataset(name, data=np.array([value], dtype="<i4"), track_times=False)


def ints(group, name, values):
    group.create_dataset(name, data=np.asarray(values, dtype="<i4"), track_times=False)


def doubles(group, name, values):
    group.create_dataset(name, data=np.asarray(values, dtype="<f8"), track_times=False)


def fixed_string(group, name, text):
    """Scalar, fixed-length, NUL-terminated ASCII: what H5LTmake_dataset_string writes."""
    raw = text.encode("ascii")
    tid = h5py.h5t.C_S1.copy()
    tid.set_size(len(raw) + 1)
    tid.set_strpad(h5py.h5t.STR_NULLTERM)
    space = h5py.h5s.create(h5py.h5s.SCALAR)
    dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
    dcpl.set_obj_track_times(False)  # reproducible files
    dset = h5py.h5d.create(group.id, name.encode("ascii"), tid, space, dcpl=dcpl)
    dset.write(h5py.h5s.ALL, h5py.h5s.ALL, np.array(raw + b"\0", dtype="S%d" % (len(raw) + 1)))


def write_matrix(group, m, n, nz, nzmax, p, i, x):
    """An fclib_matrix: nz = -1 compressed columns, -2 compressed rows, >= 0 triplets."""
    int1(group, "nzmax", nzmax)
    int1(group, "m", m)
    int1(group, "n", n)
    int1(group, "nz", nz)
    ints(group, "p", p)
    ints(group, "i", i)
    doubles(group, "x", x)
