"""Sparse linear maps on the device: ``y = M x`` and ``x = M^T y`` for a CSR matrix ``M``.

The resampling maps of lfcl/grid/resampling.py (the forward operator ``A`` of any
lens grid, and the map from a demosaiced sensor image to the regular light
field) are sparse with at most 4 entries a row. Both directions run as gathers
(lfcl/kernels/resample.cl): one work-item per output element sums its row, and the
adjoint gathers with ``M^T``, transposed once on the host, so nothing is
accumulated with atomics. ``planes`` stacked inputs share one matrix (a map
applied to each colour plane). Values are float32 on the device; the numpy twins
compute with scipy.sparse in the input's precision.

Example::

    >>> import numpy as np, scipy.sparse
    >>> from lfcl.ops.resample import sparse_apply_np, sparse_adjoint_np
    >>> M = scipy.sparse.csr_matrix(np.array([[0.5, 0.5, 0.0], [0.0, 0.0, 1.0]]))
    >>> sparse_apply_np(M, np.array([2.0, 4.0, 1.0]))
    array([3., 1.])
    >>> sparse_adjoint_np(M, np.array([1.0, 2.0]))
    array([0.5, 0.5, 2. ])
"""

from __future__ import annotations

import numpy as np
import scipy.sparse

from . import check_device_array, output

GROUP = 64  # global sizes are padded to a multiple of this, so any runtime can pick a wide work-group

_INDEX_LIMIT = np.iinfo(np.int32).max


def _stacked(vector: np.ndarray, planes: int, length: int, name: str) -> np.ndarray:
    vector = np.asarray(vector)
    if vector.size != planes * length:
        raise ValueError(f"{name} must hold {planes} x {length} values, got shape {vector.shape}")
    return vector.reshape(planes, length)


def sparse_apply_np(matrix, x: np.ndarray, planes: int = 1) -> np.ndarray:
    """M x for each of ``planes`` stacked inputs: ``[planes * ncols]`` -> ``[planes * nrows]`` (flat)."""
    matrix = scipy.sparse.csr_matrix(matrix)
    x = _stacked(x, planes, matrix.shape[1], "x")
    dtype = np.result_type(x.dtype, np.float32)
    return np.asarray(matrix @ x.T).T.astype(dtype, copy=False).ravel()


def sparse_adjoint_np(matrix, y: np.ndarray, planes: int = 1) -> np.ndarray:
    """M^T y for each of ``planes`` stacked inputs: ``[planes * nrows]`` -> ``[planes * ncols]`` (flat)."""
    return sparse_apply_np(scipy.sparse.csr_matrix(matrix).T, y, planes)


def _device_csr(runtime, matrix: scipy.sparse.csr_matrix):
    """(row pointers, column indices, values) of a CSR matrix as int32 / float32 device arrays."""
    if matrix.nnz > _INDEX_LIMIT or max(matrix.shape) > _INDEX_LIMIT:
        raise ValueError(f"a {matrix.shape[0]}x{matrix.shape[1]} sparse map with {matrix.nnz} entries "
                         "exceeds 32-bit indices")
    values = np.asarray(matrix.data, np.float32)
    if not np.all(np.isfinite(values)):
        raise ValueError("a sparse map holds NaN or Inf values")
    # a zero-length buffer cannot be created: pad the index and value arrays to one element
    col = matrix.indices.astype(np.int32) if matrix.nnz else np.zeros(1, np.int32)
    val = values if matrix.nnz else np.zeros(1, np.float32)
    return (runtime.to_device(matrix.indptr.astype(np.int32)), runtime.to_device(col), runtime.to_device(val))


def multiply(runtime, x, y, out=None):
    """out = x .* y element-wise (float32 device arrays of one shape; ``out`` may be ``x`` or ``y``)."""
    from .linalg import elementwise_size

    check_device_array(x, x.shape, "x")
    check_device_array(y, x.shape, "y")
    out = output(runtime, out, x.shape)
    if x.size:
        runtime.launch("resample", "multiply", elementwise_size(x.size), x.data, y.data, out.data, np.uint64(x.size))
    return out


class SparseOperator:
    """``M`` and ``M^T`` of a sparse matrix on the device, for ``planes`` stacked vectors.

    ``in_shape`` / ``out_shape``: the device array shapes of ``x`` and ``M x``
    (default flat ``(planes * ncols,)`` / ``(planes * nrows,)``).

    Example::

        >>> from lfcl.device import get_runtime
        >>> rt = get_runtime()
        >>> M = scipy.sparse.csr_matrix(np.array([[0.5, 0.5, 0.0], [0.0, 0.0, 1.0]]))
        >>> op = SparseOperator(rt, M)
        >>> op.forward(rt.to_device(np.array([2, 4, 1], np.float32))).get()
        array([3., 1.], dtype=float32)
    """

    def __init__(self, runtime, matrix, planes: int = 1, in_shape=None, out_shape=None):
        self.runtime = runtime
        matrix = scipy.sparse.csr_matrix(matrix)
        matrix.sum_duplicates()
        matrix.sort_indices()
        self.nrows, self.ncols = (int(n) for n in matrix.shape)
        if min(self.nrows, self.ncols) < 1:
            raise ValueError(f"a sparse map must have at least one row and column, got {matrix.shape}")
        self.planes = int(planes)
        self.in_shape = tuple(in_shape) if in_shape is not None else (self.planes * self.ncols,)
        self.out_shape = tuple(out_shape) if out_shape is not None else (self.planes * self.nrows,)
        if int(np.prod(self.in_shape)) != self.planes * self.ncols:
            raise ValueError(f"in_shape {self.in_shape} does not hold {self.planes} x {self.ncols} values")
        if int(np.prod(self.out_shape)) != self.planes * self.nrows:
            raise ValueError(f"out_shape {self.out_shape} does not hold {self.planes} x {self.nrows} values")
        self.matrix = matrix
        self._forward = _device_csr(runtime, matrix)
        self._adjoint = _device_csr(runtime, matrix.T.tocsr())

    def _size(self, rows: int, planes: int) -> tuple[int, int]:
        return (-(-rows // GROUP) * GROUP, planes)

    def _gather(self, kernel, csr, rows, cols, planes, x, *extra, out):
        self.runtime.launch("resample", kernel, self._size(rows, planes), *(a.data for a in csr), x.data,
                            *extra, out.data, np.int32(rows), np.int32(cols))
        return out

    def forward(self, x, out=None):
        """out = M x."""
        check_device_array(x, self.in_shape, "x")
        out = output(self.runtime, out, self.out_shape)
        return self._gather("csr_gather", self._forward, self.nrows, self.ncols, self.planes, x, out=out)

    def forward_scaled(self, x, scale, out=None):
        """out = scale .* (M x), ``scale`` one float per row (shared by the planes)."""
        check_device_array(x, self.in_shape, "x")
        check_device_array(scale, (self.nrows,), "scale")
        out = output(self.runtime, out, self.out_shape)
        return self._gather("csr_gather_scaled", self._forward, self.nrows, self.ncols, self.planes, x,
                            scale.data, out=out)

    def adjoint(self, y, out=None):
        """out = M^T y."""
        check_device_array(y, self.out_shape, "y")
        out = output(self.runtime, out, self.in_shape)
        return self._gather("csr_gather", self._adjoint, self.ncols, self.nrows, self.planes, y, out=out)

    def adjoint_add(self, y, add, alpha: float, out=None):
        """out = M^T y + alpha * add; ``out`` may be ``add`` itself (not ``y``)."""
        check_device_array(y, self.out_shape, "y")
        check_device_array(add, self.in_shape, "add")
        out = output(self.runtime, out, self.in_shape)
        if out.data == y.data:
            raise ValueError("out must not be y")
        return self._gather("csr_gather_add", self._adjoint, self.ncols, self.nrows, self.planes, y,
                            add.data, np.float32(alpha), out=out)

    def residual(self, x, b, sqrt_weights, out=None):
        """out = sqrt_weights .* (M x - b) (one plane): the weighted misfit of a data term."""
        if self.planes != 1:
            raise ValueError("residual needs a one-plane map")
        check_device_array(x, self.in_shape, "x")
        for array, name in ((b, "b"), (sqrt_weights, "sqrt_weights")):
            check_device_array(array, (self.nrows,), name)
        out = output(self.runtime, out, (self.nrows,))
        self.runtime.launch("resample", "csr_residual", self._size(self.nrows, 1)[:1], *(a.data for a in self._forward),
                            x.data, b.data, sqrt_weights.data, out.data, np.int32(self.nrows))
        return out
