// CFA sampling A and its adjoint A^T (paper, section 3.2).
//
//   (A x)[row, col]      = x[c(row, col)][row, col]
//   (A^T b)[c][row, col] = b[row, col] if c == c(row, col), else 0
//
// with c(row, col) the Bayer colour of the sensor pixel. Global size: (W, H).

__kernel void cfa_sample(__global const float *x, __global float *b,
                         const int height, const int width, const int pattern)
{
    const int col = get_global_id(0), row = get_global_id(1);
    if (col >= width || row >= height) return;
    const size_t plane = (size_t)height * width;
    const size_t i = (size_t)row * width + col;
    b[i] = x[bayer_colour(row, col, pattern) * plane + i];
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
