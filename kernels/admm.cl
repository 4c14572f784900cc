// The ADMM x-update's normal operator and its Jacobi preconditioner (paper, 3.4):
//
//   M x = (A^T A + rho D^T D) x
//
// A^T A keeps each pixel's own colour (a 0/1 mask); D^T D is the 4D Laplacian with
// Neumann ends over the chosen dims. Both are fused into one pass so CG reads x once.
// has_next, has_prev and step_of come from common.cl.
// Global size: (W, H, 3).

__kernel void normal_apply(__global const float *x, __global float *y,
                           const int height, const int width, const int dims, const int pattern, const float rho)
{
    const int col = get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col >= width || row >= height) return;
    const size_t i = ((size_t)c * height + row) * width + col;
    const float xi = x[i];
    float laplacian = 0.0f;
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(dims & d)) continue;
        const size_t step = step_of(d, width);
        if (has_next(d, row, col, height, width)) laplacian += xi - x[i + step];
        if (has_prev(d, row, col)) laplacian += xi - x[i - step];
    }
    const float measured = bayer_colour(row, col, pattern) == c ? xi : 0.0f;
    y[i] = measured + rho * laplacian;
}

// z = r / diag(M): diag(A^T A) is the 0/1 mask, diag(D^T D) the neighbour count.
__kernel void jacobi_apply(__global const float *r, __global float *z,
                           const int height, const int width, const int dims, const int pattern, const float rho)
{
    const int col = get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col >= width || row >= height) return;
    const size_t i = ((size_t)c * height + row) * width + col;
    int neighbours = 0;
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(dims & d)) continue;
        neighbours += has_next(d, row, col, height, width) + has_prev(d, row, col);
    }
    const float diagonal = (bayer_colour(row, col, pattern) == c ? 1.0f : 0.0f) + rho * neighbours;
    // A sample with no measurement and no neighbour (1x1 lens, one dim) has a zero row.
    z[i] = diagonal > 0.0f ? r[i] / diagonal : 0.0f;
}

// The x-update's right-hand side in one pass: rhs = A^T b + rho D^T (z - u).
// z and u hold one block of 3 planes per chosen dim (u, v, s, t order).
__kernel void build_rhs(__global const float *b, __global const float *z, __global const float *u,
                        __global float *rhs,
                        const int height, const int width, const int dims, const int pattern,
                        const float rho)
{
    const int col = get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col >= width || row >= height) return;
    const size_t pixel = (size_t)row * width + col;
    const size_t n = (size_t)3 * height * width;
    const size_t i = (size_t)c * height * width + pixel;
    float divergence = 0.0f;  // D^T (z - u), a negative divergence
    size_t block = 0;
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(dims & d)) continue;
        const size_t k = block * n + i;
        if (has_prev(d, row, col)) {
            const size_t back = k - step_of(d, width);
            divergence += z[back] - u[back];
        }
        if (has_next(d, row, col, height, width)) divergence -= z[k] - u[k];
        ++block;
    }
    const float measured = bayer_colour(row, col, pattern) == c ? b[pixel] : 0.0f;
    rhs[i] = measured + rho * divergence;
}

// Exact x-update for a (u, v)-only prior: A^T A + rho D_uv^T D_uv is block diagonal,
// one UV x UV block per lens and colour (UV = PITCH_U * PITCH_V), and the block depends
// only on the colour and the Bayer parity of the lens's first pixel. `inverse` holds
// the 4 x 3 inverted blocks, ((parity * 3 + c) * UV + i) * UV + j with
// parity = 2 * ((s*U) & 1) + ((t*V) & 1), i and j = u * V + v inside the lens:
//
//   x[lens, c, i] = sum_j inverse[parity, c, i, j] * rhs[lens, c, j]
//
// Global size: (T, S * UV, 3). Neighbouring work-items are neighbouring lenses with
// the same output sample i, so they read the same row of weights.
#define UV (PITCH_U * PITCH_V)

__kernel void lens_solve(__global const float *rhs, __global float *x, __global const float *inverse,
                         const int height, const int width)
{
    const int t = get_global_id(0), si = get_global_id(1), c = get_global_id(2);
    if (t >= width / PITCH_V || si >= (height / PITCH_U) * UV) return;
    const int s = si / UV, i = si % UV;
    const int parity = (((s * PITCH_U) & 1) << 1) | ((t * PITCH_V) & 1);
    __global const float *weights = inverse + ((size_t)(parity * 3 + c) * UV + i) * UV;
    const size_t plane = (size_t)c * height * width;
    __global const float *lens = rhs + plane + (size_t)(s * PITCH_U) * width + t * PITCH_V;
    float acc = 0.0f;
    for (int du = 0; du < PITCH_U; ++du)
        for (int dv = 0; dv < PITCH_V; ++dv)
            acc += weights[du * PITCH_V + dv] * lens[(size_t)du * width + dv];
    const int row = s * PITCH_U + i / PITCH_V, col = t * PITCH_V + i % PITCH_V;
    x[plane + (size_t)row * width + col] = acc;
}
