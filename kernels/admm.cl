// The ADMM x-update's normal operator and its Jacobi preconditioner (paper, 3.4),
// with a weighted data term 1/2 ||W^(1/2) (A x - b)||^2:
//
//   M x = (A^T W A + rho D^T D) x
//
// A^T W A keeps each pixel's own colour times its weight; D^T D is the 4D Laplacian
// with Neumann ends over the chosen dims. Both are fused into one pass so CG reads x
// once. W repeats from lens to lens (an aligned grid's white-image response): the
// UV weights of one lens, `lens_weights[u * V + v]`; all ones for the paper's A^T A.
// The row-run helpers (load_row, neighbour, has_neighbour, laplacian) are in common.cl.
// The stencil kernels handle 16 columns of one row each: global size (ceil(W / 16), H, 3).
//
// CROSS_CHANNEL (build-time, 0 or 1): K stacks the cross-channel block under D,
// K = [D; D C] with C x = (x_R - x_G, x_B - x_G) (crosschannel.cl, docs/admm.md), so
//   M x = (A^T W A + rho D^T D + rho (C^T C (x) D^T D)) x,
//   C^T C = [[1, -1, 0], [-1, 2, -1], [0, -1, 1]]:
// the colours couple through the Laplacians of the colour differences.
#ifndef CROSS_CHANNEL
#define CROSS_CHANNEL 0
#endif
//
// PRIOR_MASK (build-time, 0 or 1; common.cl LINK, LAPLACIAN): the prior keeps only the
// differences whose two samples have lens weight > 0, K = M [D; D C] (`links`, the host's
// table of them), so a pixel of weight 0 has neither data nor prior: its row of M is zero and
// the solvers leave it unchanged. Without PRIOR_MASK `links` is unused.

// The data-term weights of 16 columns of one row.
inline float16 row_weights(__global const float *lens_weights, int row, int16 cols)
{
    int at[16];
    vstore16((row % PITCH_U) * PITCH_V + cols % PITCH_V, 0, at);
    float lane[16];
    for (int k = 0; k < 16; ++k)
        lane[k] = lens_weights[at[k]];
    return vload16(0, lane);
}

#if CROSS_CHANNEL
// The Laplacian D^T D of plane c of x, at 16 lanes.
inline float16 plane_laplacian(__global const float *x, int c, int row, int col0, int height, int width,
                               __global const float *links)
{
    __global const float *plane = x + c * (size_t)height * width;
    return LAPLACIAN(plane, load_row(plane + (size_t)row * width, col0, 0, width), row, col0, height, width);
}

// Row c of (C^T C (x) D^T D) x, given own = D^T D x_c: R: L(x_R - x_G), B: L(x_B - x_G),
// G: -L(x_R - x_G) - L(x_B - x_G).
inline float16 cross_laplacian(__global const float *x, int c, float16 own, int row, int col0, int height, int width,
                               __global const float *links)
{
    if (c == 1)
        return 2.0f * own - plane_laplacian(x, 0, row, col0, height, width, links)
                          - plane_laplacian(x, 2, row, col0, height, width, links);
    return own - plane_laplacian(x, 1, row, col0, height, width, links);
}
#endif

// (M x) at 16 lanes of colour plane c.
inline float16 normal_row(__global const float *x, int c, int row, int col0, int height, int width, int pattern,
                          float rho, __global const float *lens_weights, __global const float *links)
{
    __global const float *plane = x + c * (size_t)height * width;
    const float16 xi = load_row(plane + (size_t)row * width, col0, 0, width);
    const int16 cols = lane_columns(col0);
    const float16 measured = select((float16)0.0f, xi * row_weights(lens_weights, row, cols),
                                    measured_lanes(row, cols, pattern, c));
    float16 prior = LAPLACIAN(plane, xi, row, col0, height, width);
#if CROSS_CHANNEL
    prior += cross_laplacian(x, c, prior, row, col0, height, width, links);
#endif
    return measured + rho * prior;
}

__kernel void normal_apply(__global const float *x, __global float *y,
                           const int height, const int width, const int pattern, const float rho,
                           __global const float *lens_weights, __global const float *links)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col0 >= width || row >= height) return;
    store_row(normal_row(x, c, row, col0, height, width, pattern, rho, lens_weights, links),
              y + c * (size_t)height * width + (size_t)row * width, col0, width);
}

// z = r / diag(M): diag(A^T W A) is the weighted 0/1 mask, diag(D^T D) the neighbour count
// (times 1 + (C^T C)[c][c] = 2, 3, 2 with the cross-channel block).
__kernel void jacobi_apply(__global const float *r, __global float *z,
                           const int height, const int width, const int pattern, const float rho,
                           __global const float *lens_weights, __global const float *links)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col0 >= width || row >= height) return;
    const size_t offset = c * (size_t)height * width + (size_t)row * width;
    const int16 cols = lane_columns(col0);
    float16 diagonal = select((float16)0.0f, row_weights(lens_weights, row, cols), measured_lanes(row, cols, pattern, c));
    const float link = CROSS_CHANNEL ? rho * (c == 1 ? 3.0f : 2.0f) : rho;
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(DIMS & d)) continue;
        for (int dir = -1; dir <= 1; dir += 2)
            diagonal += select((float16)0.0f, (float16)link, LINK(d, dir, row, cols, height, width));
    }
    // A sample with no measurement and no neighbour (1x1 lens, one dim) has a zero row.
    const float16 ri = load_row(r + offset, col0, 0, width);
    store_row(select((float16)0.0f, ri / diagonal, diagonal > 0.0f), z + offset, col0, width);
}

// D^T (z - u) at channel ch of a gradient with `channels` planes per block (u, v, s, t
// order): a negative divergence.
inline float16 divergence_of_difference(__global const float *z, __global const float *u, int channels, int ch,
                                        int row, int col0, int height, int width,
                                        __global const float *links)
{
    const size_t plane_size = (size_t)height * width;
    const int16 cols = lane_columns(col0);
    float16 divergence = (float16)0.0f;
    int block = 0;
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(DIMS & d)) continue;
        const size_t at = (block * channels + ch) * plane_size;
        const float16 previous = neighbour(z + at, d, -1, row, col0, height, width)
                               - neighbour(u + at, d, -1, row, col0, height, width);
        const float16 own = load_row(z + at + (size_t)row * width, col0, 0, width)
                          - load_row(u + at + (size_t)row * width, col0, 0, width);
        divergence += select((float16)0.0f, previous, LINK(d, -1, row, cols, height, width));
        divergence -= select((float16)0.0f, own, LINK(d, +1, row, cols, height, width));
        ++block;
    }
    return divergence;
}

// A^T W b at 16 lanes of colour plane c.
inline float16 measured_data(__global const float *b, int c, int row, int col0, int width, int pattern,
                             __global const float *lens_weights)
{
    const int16 cols = lane_columns(col0);
    const float16 raw = load_row(b + (size_t)row * width, col0, 0, width);
    return select((float16)0.0f, raw * row_weights(lens_weights, row, cols), measured_lanes(row, cols, pattern, c));
}

// The x-update's right-hand side in one pass: rhs = A^T W b + rho D^T (z - u), or with
// `residual` non-zero the residual rhs - M x of the previous x (the exact lens solve then
// adds its correction: float32 round-off scales with the correction, not with x).
// z and u hold one block of 3 planes per chosen dim (u, v, s, t order).
__kernel void build_rhs(__global const float *b, __global const float *z, __global const float *u,
                        __global float *rhs, const int height, const int width, const int pattern,
                        const float rho, __global const float *lens_weights, __global const float *links,
                        __global const float *x, const int residual)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col0 >= width || row >= height) return;
    const float16 divergence = divergence_of_difference(z, u, 3, c, row, col0, height, width, links);
    float16 out = measured_data(b, c, row, col0, width, pattern, lens_weights) + rho * divergence;
    if (residual)
        out -= normal_row(x, c, row, col0, height, width, pattern, rho, lens_weights, links);
    store_row(out, rhs + c * (size_t)height * width + (size_t)row * width, col0, width);
}

// With the cross-channel block: rhs = A^T W b + rho D^T (z - u) + rho C^T D^T (zc - uc),
// zc and uc holding one block of 2 planes (R - G, B - G) per chosen dim.
__kernel void build_rhs_xc(__global const float *b, __global const float *z, __global const float *u,
                           __global const float *zc, __global const float *uc,
                           __global float *rhs, const int height, const int width, const int pattern,
                           const float rho, __global const float *lens_weights, __global const float *links,
                           __global const float *x, const int residual)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col0 >= width || row >= height) return;
    float16 divergence = divergence_of_difference(z, u, 3, c, row, col0, height, width, links);
    if (c != 2) {  // pair 0 (R - G): + for R, - for G
        const float16 d0 = divergence_of_difference(zc, uc, 2, 0, row, col0, height, width, links);
        divergence += c == 0 ? d0 : -d0;
    }
    if (c != 0) {  // pair 1 (B - G): + for B, - for G
        const float16 d1 = divergence_of_difference(zc, uc, 2, 1, row, col0, height, width, links);
        divergence += c == 2 ? d1 : -d1;
    }
    float16 out = measured_data(b, c, row, col0, width, pattern, lens_weights) + rho * divergence;
    if (residual)
        out -= normal_row(x, c, row, col0, height, width, pattern, rho, lens_weights, links);
    store_row(out, rhs + c * (size_t)height * width + (size_t)row * width, col0, width);
}

// r = W^(1/2) (A x - b) on the mosaic, for the objective's data term. Global size:
// (ceil(W / 16), H).
__kernel void weighted_residual(__global const float *x, __global const float *b, __global float *r,
                                const int height, const int width, const int pattern,
                                __global const float *lens_weights)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1);
    if (col0 >= width || row >= height) return;
    const size_t plane_size = (size_t)height * width, start = (size_t)row * width;
    const int16 cols = lane_columns(col0);
    float16 sampled = (float16)0.0f;  // A x: each lane's own colour
    for (int c = 0; c < 3; ++c)
        sampled = select(sampled, load_row(x + c * plane_size + start, col0, 0, width), measured_lanes(row, cols, pattern, c));
    const float16 misfit = sampled - load_row(b + start, col0, 0, width);
    store_row(sqrt(row_weights(lens_weights, row, cols)) * misfit, r + start, col0, width);
}

// Exact x-update for a (u, v)-only prior: A^T A + rho D_uv^T D_uv is block diagonal,
// one UV x UV block per lens and colour (UV = PITCH_U * PITCH_V), and the block depends
// only on the colour and the Bayer parity of the lens's first pixel,
// parity = 2 * ((s*U) & 1) + ((t*V) & 1). With i, j = u * V + v inside the lens:
//
//   x[lens, c, i] = sum_j inverse[parity, c, i, j] * rhs[lens, c, j]
//
// With CROSS_CHANNEL the colours of a lens couple: one 3UV x 3UV block per lens, and
// output colour c reads all IN_COLOURS = 3 colours of rhs, j = c' * UV + u * V + v.
//
// One work-item computes all UV outputs of two lenses of the same colour and Bayer
// parity (lens t and t + 2 of a row), 16 outputs at a time: each float16 column load
// of the weights feeds both lenses. The host stores each block transposed and padded,
// weights[(parity * 3 + c)][j][i], i padded to UV_PAD, so that column j of the block
// is BLOCKS float16 loads.
// With `accumulate` non-zero, x += inverse * rhs (rhs a residual: the solver's update form).
// With PRIOR_MASK a pixel of lens weight 0 is not written: it keeps its value (the start).
// Global size: (2 * ceil(T / 4), S, 3); work-item g takes t = 4 * (g / 2) + g % 2 and t + 2.
#define UV (PITCH_U * PITCH_V)
#define UV_PAD (((UV + 15) / 16) * 16)
#define BLOCKS (UV_PAD / 16)
#define IN_COLOURS (CROSS_CHANNEL ? 3 : 1)

__kernel void lens_solve(__global const float *rhs, __global float *x, __global const float *weights,
                         const int height, const int width, __global const float *lens_weights,
                         const int accumulate)
{
    const int g = get_global_id(0), s = get_global_id(1), c = get_global_id(2);
    const int lenses = width / PITCH_V;
    const int t = 4 * (g / 2) + g % 2;
    if (t >= lenses || s >= height / PITCH_U) return;
    const bool pair = t + 2 < lenses;
    const int parity = (((s * PITCH_U) & 1) << 1) | ((t * PITCH_V) & 1);
    __global const float *block = weights + (size_t)(parity * 3 + c) * IN_COLOURS * UV * UV_PAD;
    const size_t plane_size = (size_t)height * width;
    const size_t first = (size_t)c * plane_size + (size_t)(s * PITCH_U) * width + t * PITCH_V;
    const size_t second = pair ? first + 2 * PITCH_V : first;
    float16 acc0[BLOCKS], acc1[BLOCKS];
    for (int b = 0; b < BLOCKS; ++b)
        acc0[b] = acc1[b] = (float16)0.0f;
    for (int ci = 0; ci < IN_COLOURS; ++ci) {
        // the input colour's plane, relative to the output's (0 without CROSS_CHANNEL)
        const long shift = IN_COLOURS == 1 ? 0 : ((long)ci - c) * (long)plane_size;
        for (int u = 0; u < PITCH_U; ++u) {
            for (int v = 0; v < PITCH_V; ++v) {
                const size_t at = (size_t)u * width + v;
                const float16 r0 = (float16)rhs[first + shift + at], r1 = (float16)rhs[second + shift + at];
                __global const float *column = block + ((ci * PITCH_U + u) * PITCH_V + v) * UV_PAD;
                for (int b = 0; b < BLOCKS; ++b) {
                    const float16 w = vload16(b, column);
                    acc0[b] = fma(w, r0, acc0[b]);
                    acc1[b] = fma(w, r1, acc1[b]);
                }
            }
        }
    }
    float out0[UV_PAD], out1[UV_PAD];
    for (int b = 0; b < BLOCKS; ++b) {
        vstore16(acc0[b], b, out0);
        vstore16(acc1[b], b, out1);
    }
    for (int u = 0; u < PITCH_U; ++u) {
        for (int v = 0; v < PITCH_V; ++v) {
            if (PRIOR_MASK && !(lens_weights[u * PITCH_V + v] > 0.0f)) continue;
            const size_t at = (size_t)u * width + v;
            x[first + at] = (accumulate ? x[first + at] : 0.0f) + out0[u * PITCH_V + v];
            if (pair) x[second + at] = (accumulate ? x[second + at] : 0.0f) + out1[u * PITCH_V + v];
        }
    }
}
