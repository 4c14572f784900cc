// Forward differences D over a subset of (u, v, s, t) and the exact adjoint D^T
// (paper, section 3.3), Neumann boundary: the difference at the last sample of a
// dimension is zero.
//
//   (D_d x)[i]   = x[i + step_d] - x[i]    if i is not last along d, else 0
//   (D_d^T z)[i] = z[i - step_d] * [i is not first along d] - z[i] * [i is not last along d]
//
// On the sensor-shaped planes (row = s*U + u, col = t*V + v, W = T*V) the steps
// are u: W, v: 1, s: U*W, t: V. `dims` is a bit mask (u=1, v=2, s=4, t=8); the
// gradient holds one block of C planes per selected dim, in u, v, s, t order.
// Global size: (W, H, C).

__kernel void grad_forward(__global const float *x, __global float *z,
                           const int height, const int width, const int channels,
                           const int dims)
{
    const int col = get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col >= width || row >= height) return;
    const size_t n = (size_t)channels * height * width;
    const size_t i = ((size_t)c * height + row) * width + col;
    const float xi = x[i];
    int block = 0;
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(dims & d)) continue;
        z[block * n + i] = has_next(d, row, col, height, width)
                               ? x[i + step_of(d, width)] - xi : 0.0f;
        ++block;
    }
}

__kernel void grad_adjoint(__global const float *z, __global float *x,
                           const int height, const int width, const int channels,
                           const int dims)
{
    const int col = get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col >= width || row >= height) return;
    const size_t n = (size_t)channels * height * width;
    const size_t i = ((size_t)c * height + row) * width + col;
    float acc = 0.0f;
    int block = 0;
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(dims & d)) continue;
        __global const float *zd = z + block * n;
        if (has_prev(d, row, col)) acc += zd[i - step_of(d, width)];
        if (has_next(d, row, col, height, width)) acc -= zd[i];
        ++block;
    }
    x[i] = acc;
}

// D^T D x without the intermediate gradient: a 4D Laplacian with Neumann ends.
__kernel void grad_gram(__global const float *x, __global float *y,
                        const int height, const int width, const int channels,
                        const int dims)
{
    const int col = get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col >= width || row >= height) return;
    const size_t i = ((size_t)c * height + row) * width + col;
    const float xi = x[i];
    float acc = 0.0f;
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(dims & d)) continue;
        const size_t step = step_of(d, width);
        if (has_next(d, row, col, height, width)) acc += xi - x[i + step];
        if (has_prev(d, row, col)) acc += xi - x[i - step];
    }
    y[i] = acc;
}
