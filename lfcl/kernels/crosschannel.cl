// The cross-channel operator of the cross-channel prior: differences of the colour
// differences (after Heide et al. 2014, FlexISP, the paper's ref [8]; docs/admm.md):
//
//   C x = (x_R - x_G, x_B - x_G)                 [3, H, W] -> [2, H, W]
//   (D C x)[block d, pair p] = D_d (C x)_p        [3, H, W] -> [k, 2, H, W]
//   C^T D^T z: R += D^T z_0,  G -= D^T z_0 + D^T z_1,  B += D^T z_1
//
// D is the forward difference of gradient.cl (Neumann: 0 at the last sample of a dim),
// over the dims in DIMS, blocks in u, v, s, t order. The gradient of the colour
// differences is 0 where the colours move together (an edge of a grey or of any
// constant hue) and large where one channel has an edge the others lack: the colour
// fringes a demosaicer makes at high frequencies.
// Stencils on runs of 16 columns of one row (common.cl). Global sizes:
// xc_forward (ceil(W / 16), H, 2); xc_adjoint (ceil(W / 16), H, 3).
// PRIOR_MASK=1: M D C and C^T D^T M, the differences masked as in gradient.cl.

// D^T applied to one plane `zd` of the gradient block along dim d, at 16 lanes.
inline float16 difference_adjoint(__global const float *zd, int d, int row, int col0, int16 cols,
                                  int height, int width, __global const float *links)
{
    const float16 previous = neighbour(zd, d, -1, row, col0, height, width);
    const float16 own = load_row(zd + (size_t)row * width, col0, 0, width);
    return select((float16)0.0f, previous, LINK(d, -1, row, cols, height, width))
         - select((float16)0.0f, own, LINK(d, +1, row, cols, height, width));
}

__kernel void xc_forward(__global const float *x, __global float *z, const int height, const int width,
                         __global const float *links)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1), p = get_global_id(2);
    if (col0 >= width || row >= height) return;
    const size_t plane_size = (size_t)height * width;
    __global const float *colour = x + (p == 0 ? 0 : 2) * plane_size;  // R or B
    __global const float *green = x + plane_size;
    const int16 cols = lane_columns(col0);
    const size_t start = (size_t)row * width;
    const float16 own = load_row(colour + start, col0, 0, width) - load_row(green + start, col0, 0, width);
    int block = 0;
    #pragma unroll
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(DIMS & d)) continue;
        const float16 next = neighbour(colour, d, +1, row, col0, height, width)
                           - neighbour(green, d, +1, row, col0, height, width);
        const float16 diff = select((float16)0.0f, next - own, LINK(d, +1, row, cols, height, width));
        store_row(diff, z + (block * 2 + p) * plane_size + start, col0, width);
        ++block;
    }
}

// x = C^T D^T z, or x += C^T D^T z when `accumulate` is non-zero (the solver adds the
// cross-channel part to D^T of the TV part).
__kernel void xc_adjoint(__global const float *z, __global float *x, const int height, const int width,
                         const int accumulate, __global const float *links)
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
        __global const float *zd = z + block * 2 * plane_size;
        if (c != 2) {  // pair 0 (R - G) reaches R and G
            const float16 div0 = difference_adjoint(zd, d, row, col0, cols, height, width, links);
            acc += c == 0 ? div0 : -div0;
        }
        if (c != 0) {  // pair 1 (B - G) reaches B and G
            const float16 div1 = difference_adjoint(zd + plane_size, d, row, col0, cols, height, width, links);
            acc += c == 2 ? div1 : -div1;
        }
        ++block;
    }
    __global float *out = x + c * plane_size + (size_t)row * width;
    if (accumulate)
        acc += load_row(out, col0, 0, width);
    store_row(acc, out, col0, width);
}
