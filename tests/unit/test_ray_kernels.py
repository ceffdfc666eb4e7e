"""The embree ray set-up of ``Mandrel.intersect_segments`` (``_kernels.mesh.segment_rays``)
against the whole-array NumPy set-up it replaces."""

from __future__ import annotations

import numpy as np

from preform._kernels.mesh import segment_rays


def numpy_rays(starts, ends, offset, diagonal, origin, scale):
    """dirs, length, live indices and the float32 embree rays, in whole-array NumPy."""
    d = ends - starts
    length = np.linalg.norm(d, axis=1)
    ok = length > 0
    dirs = np.zeros_like(d)
    dirs[ok] = d[ok] / length[ok, None]
    idx = np.nonzero(ok)[0]
    live = idx[length[idx] > offset]
    o = starts[live] + offset * dirs[live]
    slack = 1e-6 * (length[live] + diagonal)
    far = ((length[live] - offset + slack) * scale).astype(np.float32)
    o32 = ((np.array(o, dtype=np.float64) - origin) * scale).astype(np.float32)
    return dirs, length, live, o32, dirs[live].astype(np.float32), far


def test_segment_rays_equal_numpy_bit_for_bit():
    rng = np.random.default_rng(7)
    n = 5000
    starts = rng.normal(scale=0.3, size=(n, 3))
    ends = starts + rng.normal(scale=0.5, size=(n, 3)) * rng.uniform(0, 1, (n, 1)) ** 4
    ends[:20] = starts[:20]                               # zero length: no ray
    ends[20:40] = starts[20:40] + 1e-9                    # shorter than the offset: no ray
    offset, diagonal, origin, scale = 1e-7, 1.7, np.array([-0.9, -0.8, -1.1]), 100.0 / 1.7
    dirs, length, live = np.empty((n, 3)), np.empty(n), np.empty(n, dtype=np.int64)
    o32, d32, far32 = (np.empty((n, 3), np.float32), np.empty((n, 3), np.float32),
                       np.empty(n, np.float32))
    m = segment_rays(starts, ends, offset, diagonal, origin, scale, dirs, length, live, o32, d32, far32)
    ref = numpy_rays(starts, ends, offset, diagonal, origin, scale)
    assert m == len(ref[2]) < n - 39
    for got, want in zip((dirs, length, live[:m], o32[:m], d32[:m], far32[:m]), ref):
        np.testing.assert_array_equal(got, want)
