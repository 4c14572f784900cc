// CFA sampling A and its adjoint A^T (paper, section 3.2).
//
//   (A x)[row, col]      = x[c(row, col)][row, col]
//   (A^T b)[c][row, col] = b[row, col] if c == c(row, col), else 0
//
// with c(row, col) the Bayer colour of the sensor pixel. Global size: (W, H), one
// work-item per pixel; cfa_sample: (ceil(W / 16), H), 16 columns per work-item.

__kernel void cfa_sample(__global const float *x, __global float *b,
                         const int height, const int width, const int pattern)
{
    // 16 columns of one row per work-item: a row holds two colours, alternating, so
    // read both planes' runs and keep each lane's own (one pass over two planes,
    // instead of a gather across three).
    const int col0 = 16 * get_global_id(0), row = get_global_id(1);
    if (col0 >= width || row >= height) return;
    const size_t plane = (size_t)height * width;
    const size_t start = (size_t)row * width;
    const int even = bayer_colour(row, col0 & ~1, pattern), odd = bayer_colour(row, col0 | 1, pattern);
    const float16 at_even = load_row(x + even * plane + start, col0, 0, width);
    const float16 at_odd = load_row(x + odd * plane + start, col0, 0, width);
    const int16 odd_lane = (lane_columns(col0) & 1) == 1;
    store_row(select(at_even, at_odd, odd_lane), b + start, col0, width);
}

__kernel void cfa_adjoint(__global const float *b, __global float *x,
                          const int height, const int width, const int pattern)
{
    const int col = get_global_id(0), row = get_global_id(1);
    if (col >= width || row >= height) return;
    const size_t plane = (size_t)height * width;
    const size_t i = (size_t)row * width + col;
    const int c = bayer_colour(row, col, pattern);
    const float value = b[i];
    x[i]             = c == 0 ? value : 0.0f;
    x[plane + i]     = c == 1 ? value : 0.0f;
    x[2 * plane + i] = c == 2 ? value : 0.0f;
}

// A^T A x: keep each pixel's own colour, zero the two it did not measure.
__kernel void cfa_gram(__global const float *x, __global float *y,
                       const int height, const int width, const int pattern)
{
    const int col = get_global_id(0), row = get_global_id(1);
    if (col >= width || row >= height) return;
    const size_t plane = (size_t)height * width;
    const size_t i = (size_t)row * width + col;
    const int c = bayer_colour(row, col, pattern);
    y[i]             = c == 0 ? x[i] : 0.0f;
    y[plane + i]     = c == 1 ? x[plane + i] : 0.0f;
    y[2 * plane + i] = c == 2 ? x[2 * plane + i] : 0.0f;
}
