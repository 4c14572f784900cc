// Sparse matrices in CSR form (row pointers, column indices, values), applied by gathering:
// one work-item per output row and plane, so no two work-items write one element and no
// atomics are needed. The adjoint M^T is the same gather with the transposed matrix, which
// the host builds once (lfcl/ops/resample.py). The resampling maps of lfcl/grid/resampling.py
// have at most 4 entries a row (their transposes about as many), so a plain loop per row.
//
// `planes` stacked inputs/outputs: plane p of x starts at p * ncols, of the output at
// p * nrows (one matrix for the three colour planes). Global size: (rows padded, planes).

inline float csr_row(__global const int *rowptr, __global const int *col, __global const float *val,
                     __global const float *x, const int row)
{
    float acc = 0.0f;
    const int end = rowptr[row + 1];
    for (int k = rowptr[row]; k < end; ++k)
        acc = fma(val[k], x[col[k]], acc);
    return acc;
}

// out = M x
__kernel void csr_gather(__global const int *rowptr, __global const int *col, __global const float *val,
                         __global const float *x, __global float *out, const int nrows, const int ncols)
{
    const int row = get_global_id(0);
    const size_t p = get_global_id(1);
    if (row >= nrows) return;
    out[p * nrows + row] = csr_row(rowptr, col, val, x + p * ncols, row);
}

// out = scale .* (M x)   (scale: one value per row, shared by the planes)
__kernel void csr_gather_scaled(__global const int *rowptr, __global const int *col, __global const float *val,
                                __global const float *x, __global const float *scale, __global float *out,
                                const int nrows, const int ncols)
{
    const int row = get_global_id(0);
    const size_t p = get_global_id(1);
    if (row >= nrows) return;
    out[p * nrows + row] = scale[row] * csr_row(rowptr, col, val, x + p * ncols, row);
}

// out = M x + alpha * add   (out may be add: each element is read before it is written)
__kernel void csr_gather_add(__global const int *rowptr, __global const int *col, __global const float *val,
                             __global const float *x, __global const float *add, const float alpha,
                             __global float *out, const int nrows, const int ncols)
{
    const int row = get_global_id(0);
    const size_t p = get_global_id(1);
    if (row >= nrows) return;
    const size_t i = p * nrows + row;
    out[i] = csr_row(rowptr, col, val, x + p * ncols, row) + alpha * add[i];
}

// out = sqrt_w .* (M x - b): the weighted residual of a data term (one plane)
__kernel void csr_residual(__global const int *rowptr, __global const int *col, __global const float *val,
                           __global const float *x, __global const float *b, __global const float *sqrt_w,
                           __global float *out, const int nrows)
{
    const int row = get_global_id(0);
    if (row >= nrows) return;
    out[row] = sqrt_w[row] * (csr_row(rowptr, col, val, x, row) - b[row]);
}

// out = x .* y over n floats (the Jacobi preconditioner, W b); out may be x or y.
// Work-item k handles the chunk of 16 floats [16k, 16k + 16), as in linalg.cl.
__kernel void multiply(__global const float *x, __global const float *y, __global float *out, const ulong n)
{
    const ulong k = get_global_id(0);
    if (k * LANES >= n) return;
    store_chunk(load_chunk(x, k, n) * load_chunk(y, k, n), out, k, n);
}
