// Forward differences D over a subset of (u, v, s, t) and the exact adjoint D^T
// (paper, section 3.3), Neumann boundary: the difference at the last sample of a
// dimension is zero.
//
//   (D_d x)[i]   = x[i + step_d] - x[i]    if i is not last along d, else 0
//   (D_d^T z)[i] = z[i - step_d] * [i is not first along d] - z[i] * [i is not last along d]
//
// On the sensor-shaped planes (row = s*U + u, col = t*V + v, W = T*V) the steps
// are u: W, v: 1, s: U*W, t: V. DIMS (a build-time constant) is a bit mask (u=1, v=2,
// s=4, t=8); the
// gradient holds one block of C planes per selected dim, in u, v, s, t order.
// Each work-item handles 16 columns of one row. Global size: (ceil(W / 16), H, C).
//
// PRIOR_MASK=1 (build-time): the masked operator M D, D^T M and D^T M D, M keeping only the
// differences whose two samples both have lens weight > 0 (`links`, tabulated from the white
// image's data-term weights; common.cl linked()). Without it `links` is unused.

__kernel void grad_forward(__global const float *x, __global float *z,
                           const int height, const int width, const int channels,
                           __global const float *links)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col0 >= width || row >= height) return;
    const size_t plane_size = (size_t)height * width;
    __global const float *plane = x + c * plane_size;
    const int16 cols = lane_columns(col0);
    const float16 xi = load_row(plane + (size_t)row * width, col0, 0, width);
    int block = 0;
    #pragma unroll
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(DIMS & d)) continue;
        const float16 next = neighbour(plane, d, +1, row, col0, height, width);
        const float16 diff = select((float16)0.0f, next - xi, LINK(d, +1, row, cols, height, width));
        store_row(diff, z + (block * channels + c) * plane_size + (size_t)row * width, col0, width);
        ++block;
    }
}

__kernel void grad_adjoint(__global const float *z, __global float *x,
                           const int height, const int width, const int channels,
                           __global const float *links)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col0 >= width || row >= height) return;
    const size_t plane_size = (size_t)height * width;
    const int16 cols = lane_columns(col0);
    float16 acc = (float16)0.0f;
    int block = 0;
    #pragma unroll
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(DIMS & d)) continue;
        __global const float *zd = z + (block * channels + c) * plane_size;
        const float16 previous = neighbour(zd, d, -1, row, col0, height, width);
        const float16 own = load_row(zd + (size_t)row * width, col0, 0, width);
        acc += select((float16)0.0f, previous, LINK(d, -1, row, cols, height, width));
        acc -= select((float16)0.0f, own, LINK(d, +1, row, cols, height, width));
        ++block;
    }
    store_row(acc, x + c * plane_size + (size_t)row * width, col0, width);
}

// D^T D x without the intermediate gradient (laplacian() is in common.cl).
__kernel void grad_gram(__global const float *x, __global float *y,
                        const int height, const int width, const int channels,
                        __global const float *links)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col0 >= width || row >= height) return;
    const size_t plane_size = (size_t)height * width;
    __global const float *plane = x + c * plane_size;
    const float16 xi = load_row(plane + (size_t)row * width, col0, 0, width);
    store_row(LAPLACIAN(plane, xi, row, col0, height, width), y + c * plane_size + (size_t)row * width, col0, width);
}
