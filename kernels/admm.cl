// The ADMM x-update's normal operator and its Jacobi preconditioner (paper, 3.4):
//
//   M x = (A^T A + rho D^T D) x
//
// A^T A keeps each pixel's own colour (a 0/1 mask); D^T D is the 4D Laplacian with
// Neumann ends over the chosen dims. Both are fused into one pass so CG reads x once.
// has_next, has_prev and step_of come from common.cl.
// Global size: (W, H, 3).

__kernel void normal_apply(__global const float *x, __global float *y,
                           const int height, const int width, const int U, const int V,
                           const int dims, const int pattern, const float rho)
{
    const int col = get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col >= width || row >= height) return;
    const size_t i = ((size_t)c * height + row) * width + col;
    const float xi = x[i];
    float laplacian = 0.0f;
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(dims & d)) continue;
        const size_t step = step_of(d, width, U, V);
        if (has_next(d, row, col, height, width, U, V)) laplacian += xi - x[i + step];
        if (has_prev(d, row, col, U, V)) laplacian += xi - x[i - step];
    }
    const float measured = bayer_colour(row, col, pattern) == c ? xi : 0.0f;
    y[i] = measured + rho * laplacian;
}

// z = r / diag(M): diag(A^T A) is the 0/1 mask, diag(D^T D) the neighbour count.
__kernel void jacobi_apply(__global const float *r, __global float *z,
                           const int height, const int width, const int U, const int V,
                           const int dims, const int pattern, const float rho)
{
    const int col = get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col >= width || row >= height) return;
    const size_t i = ((size_t)c * height + row) * width + col;
    int neighbours = 0;
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(dims & d)) continue;
        neighbours += has_next(d, row, col, height, width, U, V) + has_prev(d, row, col, U, V);
    }
    const float diagonal = (bayer_colour(row, col, pattern) == c ? 1.0f : 0.0f) + rho * neighbours;
    // A sample with no measurement and no neighbour (1x1 lens, one dim) has a zero row.
    z[i] = diagonal > 0.0f ? r[i] / diagonal : 0.0f;
}
