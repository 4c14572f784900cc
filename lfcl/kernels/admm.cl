// The ADMM x-update's normal operator and its Jacobi preconditioner (paper, 3.4),
// with a weighted data term 1/2 ||W^(1/2) (A x - b)||^2:
//
//   M x = (A^T W A + rho D^T D) x
//
// A^T W A keeps each pixel's own colour times its weight; D^T D is the 4D Laplacian
// with Neumann ends over the chosen dims. Both are fused into one pass so CG reads x
// once. W repeats from lens to lens (an aligned grid's white-image response): the
// UV weights of one lens, `weight_runs[u * V + v]`; all ones for the paper's A^T A.
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
// PRIOR_MASK (build-time, 1 when some lens weight is 0; common.cl LINK, LAPLACIAN): the prior
// keeps only the differences whose two samples have lens weight > 0, K = M [D; D C] (`links`,
// the host's table of them), so a pixel of weight 0 has neither data nor prior: its row of M is
// zero and the solvers leave it unchanged. Without PRIOR_MASK `links` is unused.

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
                          float rho, __global const float *weight_runs, __global const float *links)
{
    __global const float *plane = x + c * (size_t)height * width;
    const float16 xi = load_row(plane + (size_t)row * width, col0, 0, width);
    const int16 cols = lane_columns(col0);
    const float16 measured = select((float16)0.0f, xi * row_weights(weight_runs, row, cols),
                                    measured_lanes(row, cols, pattern, c));
    float16 prior = LAPLACIAN(plane, xi, row, col0, height, width);
#if CROSS_CHANNEL
    prior += cross_laplacian(x, c, prior, row, col0, height, width, links);
#endif
    return measured + rho * prior;
}

__kernel void normal_apply(__global const float *x, __global float *y,
                           const int height, const int width, const int pattern, const float rho,
                           __global const float *weight_runs, __global const float *links)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col0 >= width || row >= height) return;
    store_row(normal_row(x, c, row, col0, height, width, pattern, rho, weight_runs, links),
              y + c * (size_t)height * width + (size_t)row * width, col0, width);
}

// z = r / diag(M): diag(A^T W A) is the weighted 0/1 mask, diag(D^T D) the neighbour count
// (times 1 + (C^T C)[c][c] = 2, 3, 2 with the cross-channel block).
__kernel void jacobi_apply(__global const float *r, __global float *z,
                           const int height, const int width, const int pattern, const float rho,
                           __global const float *weight_runs, __global const float *links)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col0 >= width || row >= height) return;
    const size_t offset = c * (size_t)height * width + (size_t)row * width;
    const int16 cols = lane_columns(col0);
    float16 diagonal = select((float16)0.0f, row_weights(weight_runs, row, cols), measured_lanes(row, cols, pattern, c));
    const float link = CROSS_CHANNEL ? rho * (c == 1 ? 3.0f : 2.0f) : rho;
    #pragma unroll
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(DIMS & d)) continue;
        #pragma unroll
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
    #pragma unroll
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
                             __global const float *weight_runs)
{
    const int16 cols = lane_columns(col0);
    const float16 raw = load_row(b + (size_t)row * width, col0, 0, width);
    return select((float16)0.0f, raw * row_weights(weight_runs, row, cols), measured_lanes(row, cols, pattern, c));
}

// The x-update's right-hand side in one pass: rhs = A^T W b + rho D^T (z - u), or with
// `residual` non-zero the residual rhs - M x of the previous x (the exact lens solve then
// adds its correction: float32 round-off scales with the correction, not with x).
// z and u hold one block of 3 planes per chosen dim (u, v, s, t order).
__kernel void build_rhs(__global const float *b, __global const float *z, __global const float *u,
                        __global float *rhs, const int height, const int width, const int pattern,
                        const float rho, __global const float *weight_runs, __global const float *links,
                        __global const float *x, const int residual)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col0 >= width || row >= height) return;
    const float16 divergence = divergence_of_difference(z, u, 3, c, row, col0, height, width, links);
    float16 out = measured_data(b, c, row, col0, width, pattern, weight_runs) + rho * divergence;
    if (residual)
        out -= normal_row(x, c, row, col0, height, width, pattern, rho, weight_runs, links);
    store_row(out, rhs + c * (size_t)height * width + (size_t)row * width, col0, width);
}

// With the cross-channel block: rhs = A^T W b + rho D^T (z - u) + rho C^T D^T (zc - uc),
// zc and uc holding one block of 2 planes (R - G, B - G) per chosen dim.
__kernel void build_rhs_xc(__global const float *b, __global const float *z, __global const float *u,
                           __global const float *zc, __global const float *uc,
                           __global float *rhs, const int height, const int width, const int pattern,
                           const float rho, __global const float *weight_runs, __global const float *links,
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
    float16 out = measured_data(b, c, row, col0, width, pattern, weight_runs) + rho * divergence;
    if (residual)
        out -= normal_row(x, c, row, col0, height, width, pattern, rho, weight_runs, links);
    store_row(out, rhs + c * (size_t)height * width + (size_t)row * width, col0, width);
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
// sums[change_at + item] (item = (c * S + s) * 2 ceil(T / 4) + g) gets the work-item's sum of
// squared updates (the history's rms change), 0 for the work-items past the grid.
#define UV (PITCH_U * PITCH_V)
#define UV_PAD (((UV + 15) / 16) * 16)
#define BLOCKS (UV_PAD / 16)
#define IN_COLOURS (CROSS_CHANNEL ? 3 : 1)

__kernel void lens_solve(__global const float *rhs, __global float *x, __global const float *weights,
                         const int height, const int width, __global const float *weight_runs,
                         const int accumulate, __global float *sums, const int change_at)
{
    const int g = get_global_id(0), s = get_global_id(1), c = get_global_id(2);
    const int lenses = width / PITCH_V;
    const int t = 4 * (g / 2) + g % 2;
    // this work-item's sum of squared updates, sum (x_new - x_old)^2 (x_new^2 without `accumulate`)
    __global float *change = sums + change_at + ((size_t)c * get_global_size(1) + s) * get_global_size(0) + g;
    if (t >= lenses || s >= height / PITCH_U) {
        *change = 0.0f;
        return;
    }
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
    float squares = 0.0f;
    for (int u = 0; u < PITCH_U; ++u) {
        for (int v = 0; v < PITCH_V; ++v) {
            if (PRIOR_MASK && !(weight_runs[(u * PITCH_V + v) * 16] > 0.0f)) continue;
            const size_t at = (size_t)u * width + v;
            const float d0 = out0[u * PITCH_V + v], d1 = out1[u * PITCH_V + v];
            x[first + at] = (accumulate ? x[first + at] : 0.0f) + d0;
            squares += d0 * d0;
            if (pair) {
                x[second + at] = (accumulate ? x[second + at] : 0.0f) + d1;
                squares += d1 * d1;
            }
        }
    }
    *change = squares;
}

// --- the rest of one iteration in two passes, each leaving the history's sums as per-row
// partials (one float per row of a plane: item = c * height + row) so that the host adds a few
// thousand floats in float64 instead of running separate reduction passes. Each work-item walks
// one whole row in runs of 16 columns, accumulating with TwoSum (the rounding errors are kept in
// a second float, as in reduce.cl); every summed term is >= 0, so the per-row float result is
// accurate to a few float ulps. Global size: (H, 3).

// (s, e) += t with s + e the running total (Knuth's TwoSum: exact error, no branch).
inline void add_exact(float16 *s, float16 *e, float16 t)
{
    const float16 sum = *s + t;
    const float16 z = sum - *s;
    *e += (*s - (sum - z)) + (t - z);
    *s = sum;
}

// The 16 lanes' (s + e), added in float (terms >= 0: relative error a few ulps).
inline float lanes_total(float16 s, float16 e)
{
    const float16 t = s + e;
    const float8 h8 = t.lo + t.hi;
    const float4 h4 = h8.lo + h8.hi;
    const float2 h2 = h4.lo + h4.hi;
    return h2.x + h2.y;
}

// S_kappa(v) = sign(v) max(|v| - kappa, 0), NaN propagating (shrink.cl's soft threshold).
inline float16 soft_threshold16(float16 v, float kappa)
{
    const float16 m = fabs(v) - kappa;
    return copysign(select(m, (float16)0.0f, m < 0.0f), v);
}

// The z/u step with D x computed on the fly (no D x buffer), per chosen dim d:
//   dx = (M D x)_d,  v = dx + u,  z' = S_kappa(v),  u' = v - z',  dz = z' - z,
// in place on z and u (each element is read and written by its own work-item only).
// Row sums: sums[0 * items + item] = sum (dx - z')^2 (primal residual^2),
// sums[1 * items + item] = sum |dx| (TV), sums[2 * items + item] = sum dx^2 (||K x||^2),
// items = 3 * height.
__kernel void zu_step(__global const float *x, __global float *z, __global float *u, __global float *dz,
                      const float kappa, const int height, const int width,
                      __global const float *links, __global float *sums)
{
    const int row = get_global_id(0), c = get_global_id(1);
    if (row >= height) return;
    const size_t plane_size = (size_t)height * width, start = (size_t)row * width;
    __global const float *plane = x + c * plane_size;
    float16 primal = 0.0f, primal_e = 0.0f, tv = 0.0f, tv_e = 0.0f, kx = 0.0f, kx_e = 0.0f;
    for (int col0 = 0; col0 < width; col0 += 16) {
        const int16 cols = lane_columns(col0);
        const float16 xi = load_row(plane + start, col0, 0, width);
        int block = 0;
        #pragma unroll
        for (int d = 1; d <= DIM_T; d <<= 1) {
            if (!(DIMS & d)) continue;
            const float16 next = neighbour(plane, d, +1, row, col0, height, width);
            const float16 dx = select((float16)0.0f, next - xi, LINK(d, +1, row, cols, height, width));
            const size_t at = (block * 3 + c) * plane_size + start;
            const float16 v = dx + load_row(u + at, col0, 0, width);
            const float16 z_old = load_row(z + at, col0, 0, width);
            const float16 z_new = soft_threshold16(v, kappa);
            store_row(z_new, z + at, col0, width);
            store_row(v - z_new, u + at, col0, width);
            store_row(z_new - z_old, dz + at, col0, width);
            const float16 r = dx - z_new;
            add_exact(&primal, &primal_e, r * r);
            add_exact(&tv, &tv_e, fabs(dx));
            add_exact(&kx, &kx_e, dx * dx);
            ++block;
        }
    }
    const size_t item = (size_t)c * height + row, items = 3 * (size_t)height;
    sums[item] = lanes_total(primal, primal_e);
    sums[items + item] = lanes_total(tv, tv_e);
    sums[2 * items + item] = lanes_total(kx, kx_e);
}

// out = D^T M dz (plus out's own value with `accumulate`: the cross-channel block's share,
// written there first), and the objective's data term, in one pass. Row sums:
// sums[3 * items + item] = sum out^2 (dual residual^2 / rho^2),
// sums[4 * items + item] = sum over the pixels measuring colour c of w (x_c - b)^2 (the misfit
// ||W^(1/2) (A x - b)||^2, split by colour plane).
__kernel void dual_and_misfit(__global const float *dz, __global float *out, const int accumulate,
                              __global const float *x, __global const float *b,
                              const int height, const int width, const int pattern,
                              __global const float *weight_runs, __global const float *links,
                              __global float *sums)
{
    const int row = get_global_id(0), c = get_global_id(1);
    if (row >= height) return;
    const size_t plane_size = (size_t)height * width, start = (size_t)row * width;
    float16 dual = 0.0f, dual_e = 0.0f, misfit = 0.0f, misfit_e = 0.0f;
    for (int col0 = 0; col0 < width; col0 += 16) {
        const int16 cols = lane_columns(col0);
        float16 acc = (float16)0.0f;
        int block = 0;
        #pragma unroll
        for (int d = 1; d <= DIM_T; d <<= 1) {
            if (!(DIMS & d)) continue;
            __global const float *zd = dz + (block * 3 + c) * plane_size;
            const float16 previous = neighbour(zd, d, -1, row, col0, height, width);
            const float16 own = load_row(zd + start, col0, 0, width);
            acc += select((float16)0.0f, previous, LINK(d, -1, row, cols, height, width));
            acc -= select((float16)0.0f, own, LINK(d, +1, row, cols, height, width));
            ++block;
        }
        __global float *out_row = out + c * plane_size + start;
        if (accumulate)
            acc += load_row(out_row, col0, 0, width);
        store_row(acc, out_row, col0, width);
        add_exact(&dual, &dual_e, acc * acc);
        const float16 misfit_k = load_row(x + c * plane_size + start, col0, 0, width) - load_row(b + start, col0, 0, width);
        add_exact(&misfit, &misfit_e, select((float16)0.0f, row_weights(weight_runs, row, cols) * misfit_k * misfit_k,
                                             measured_lanes(row, cols, pattern, c)));
    }
    const size_t item = (size_t)c * height + row, items = 3 * (size_t)height;
    sums[3 * items + item] = lanes_total(dual, dual_e);
    sums[4 * items + item] = lanes_total(misfit, misfit_e);
}
