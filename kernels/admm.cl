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

__kernel void normal_apply(__global const float *x, __global float *y,
                           const int height, const int width, const int pattern, const float rho,
                           __global const float *lens_weights)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col0 >= width || row >= height) return;
    const size_t plane_size = (size_t)height * width;
    __global const float *plane = x + c * plane_size;
    const float16 xi = load_row(plane + (size_t)row * width, col0, 0, width);
    const int16 cols = lane_columns(col0);
    const float16 measured = select((float16)0.0f, xi * row_weights(lens_weights, row, cols),
                                    measured_lanes(row, cols, pattern, c));
    store_row(measured + rho * laplacian(plane, xi, row, col0, height, width),
              y + c * plane_size + (size_t)row * width, col0, width);
}

// z = r / diag(M): diag(A^T W A) is the weighted 0/1 mask, diag(D^T D) the neighbour count.
__kernel void jacobi_apply(__global const float *r, __global float *z,
                           const int height, const int width, const int pattern, const float rho,
                           __global const float *lens_weights)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col0 >= width || row >= height) return;
    const size_t offset = c * (size_t)height * width + (size_t)row * width;
    const int16 cols = lane_columns(col0);
    float16 diagonal = select((float16)0.0f, row_weights(lens_weights, row, cols), measured_lanes(row, cols, pattern, c));
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(DIMS & d)) continue;
        for (int dir = -1; dir <= 1; dir += 2)
            diagonal += select((float16)0.0f, (float16)rho, has_neighbour(d, dir, row, cols, height, width));
    }
    // A sample with no measurement and no neighbour (1x1 lens, one dim) has a zero row.
    const float16 ri = load_row(r + offset, col0, 0, width);
    store_row(select((float16)0.0f, ri / diagonal, diagonal > 0.0f), z + offset, col0, width);
}

// The x-update's right-hand side in one pass: rhs = A^T W b + rho D^T (z - u).
// z and u hold one block of 3 planes per chosen dim (u, v, s, t order).
__kernel void build_rhs(__global const float *b, __global const float *z, __global const float *u,
                        __global float *rhs, const int height, const int width, const int pattern,
                        const float rho, __global const float *lens_weights)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1), c = get_global_id(2);
    if (col0 >= width || row >= height) return;
    const size_t plane_size = (size_t)height * width;
    const int16 cols = lane_columns(col0);
    float16 divergence = (float16)0.0f;  // D^T (z - u), a negative divergence
    int block = 0;
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(DIMS & d)) continue;
        const size_t at = (block * 3 + c) * plane_size;
        const float16 previous = neighbour(z + at, d, -1, row, col0, height, width)
                               - neighbour(u + at, d, -1, row, col0, height, width);
        const float16 own = load_row(z + at + (size_t)row * width, col0, 0, width)
                          - load_row(u + at + (size_t)row * width, col0, 0, width);
        divergence += select((float16)0.0f, previous, has_neighbour(d, -1, row, cols, height, width));
        divergence -= select((float16)0.0f, own, has_neighbour(d, +1, row, cols, height, width));
        ++block;
    }
    const float16 raw = load_row(b + (size_t)row * width, col0, 0, width);
    const float16 measured = select((float16)0.0f, raw * row_weights(lens_weights, row, cols),
                                    measured_lanes(row, cols, pattern, c));
    store_row(measured + rho * divergence, rhs + c * plane_size + (size_t)row * width, col0, width);
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
// One work-item computes all UV outputs of two lenses of the same colour and Bayer
// parity (lens t and t + 2 of a row), 16 outputs at a time: each float16 column load
// of the weights feeds both lenses. The host stores each block transposed and padded,
// weights[(parity * 3 + c)][j][i], i padded to UV_PAD, so that column j of the block
// is BLOCKS float16 loads.
// Global size: (2 * ceil(T / 4), S, 3); work-item g takes t = 4 * (g / 2) + g % 2 and t + 2.
#define UV (PITCH_U * PITCH_V)
#define UV_PAD (((UV + 15) / 16) * 16)
#define BLOCKS (UV_PAD / 16)

__kernel void lens_solve(__global const float *rhs, __global float *x, __global const float *weights,
                         const int height, const int width)
{
    const int g = get_global_id(0), s = get_global_id(1), c = get_global_id(2);
    const int lenses = width / PITCH_V;
    const int t = 4 * (g / 2) + g % 2;
    if (t >= lenses || s >= height / PITCH_U) return;
    const bool pair = t + 2 < lenses;
    const int parity = (((s * PITCH_U) & 1) << 1) | ((t * PITCH_V) & 1);
    __global const float *block = weights + (size_t)(parity * 3 + c) * UV * UV_PAD;
    const size_t first = (size_t)c * height * width + (size_t)(s * PITCH_U) * width + t * PITCH_V;
    const size_t second = pair ? first + 2 * PITCH_V : first;
    float16 acc0[BLOCKS], acc1[BLOCKS];
    for (int b = 0; b < BLOCKS; ++b)
        acc0[b] = acc1[b] = (float16)0.0f;
    for (int u = 0; u < PITCH_U; ++u) {
        for (int v = 0; v < PITCH_V; ++v) {
            const size_t at = (size_t)u * width + v;
            const float16 r0 = (float16)rhs[first + at], r1 = (float16)rhs[second + at];
            __global const float *column = block + (u * PITCH_V + v) * UV_PAD;
            for (int b = 0; b < BLOCKS; ++b) {
                const float16 w = vload16(b, column);
                acc0[b] = fma(w, r0, acc0[b]);
                acc1[b] = fma(w, r1, acc1[b]);
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
            const size_t at = (size_t)u * width + v;
            x[first + at] = out0[u * PITCH_V + v];
            if (pair) x[second + at] = out1[u * PITCH_V + v];
        }
    }
}
