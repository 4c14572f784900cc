// The prior along the epipolar lines (lfcl/ops/epi.py, docs/admm.md "admm-epi"): differences between
// each sample and its neighbour along its local disparity line, and the exact adjoint, both as gathers.
//
// A point seen at lens (s, t) in the centre view is seen by view (u, v) at lens (s - d (u - uc),
// t - d (v - vc)), d in lenses per view step. On the sensor-shaped planes (row = s*U + u,
// col = t*V + v), for sample i = (s, t, u, v) of channel c:
//
//   u-block: z_u[i] = w_i (x(s - d_i, t, u + 1, v) - x(s, t, u, v))   (0 at u = U - 1)
//   v-block: z_v[i] = w_i (x(s, t - d_i, u, v + 1) - x(s, t, u, v))   (0 at v = V - 1)
//
// x at a fractional lens s - d_i: Catmull-Rom (Keys, a = -1/2) cubic interpolation over the 4 lenses
// floor(p) - 1 .. floor(p) + 2 along s (along t for the v-block), lens indices clamped to the frame.
// `rays` holds d_i (plane 0) and w_i (plane 1) per sample, [2, H, W], read from the lens maps by epi_ray_maps
// (bit for bit its twin lfcl/ops/epi.py ray_maps_np), so the twin and the device use the same numbers.
//
// Both work on runs of 16 columns of one row (col0 .. col0 + 15, one SIMD register on a CPU, as
// gradient.cl). The lanes of a run have their own disparities, so instead of gathering per lane, a
// kernel loops over the few lens offsets m that any lane's taps reach (`offsets`, tabulated per lens row
// by the host from epi_lens_tap_spans, lfcl/ops/epi.py offset_table) and adds, per lane, the summed weight of its
// taps on that lens times one contiguous 16-column load: vector loads only.
//
//   forward, u-block: x(s - d, t, u + 1, v) = sum_m [taps on lens s + m] x[row (s + m) U + u + 1, same cols]
//   forward, v-block: x(s, t - d, u, v + 1) = sum_m [taps on lens t + m] x[same row, col + m V + 1]
//   adjoint, u-block: target (s', u') gathers from the rows (s' + k) U + u' - 1, the taps of each lane of
//                     that source row that land on s' (k over the offsets of sources that reach s');
//   adjoint, v-block: target col' gathers from col' + k V - 1 (sources (t' + k, v' - 1)), lanes v' > 0.
//
// A source k lenses from the target puts the Catmull-Rom weight at distance |d - k| on it (d the source's
// disparity), so the adjoint evaluates that one weight per source (keys_at) instead of the source's 4 taps
// (at 128x128 lenses, charts' disparity, PoCL on 2 cores: 10.4 -> 7.4 ms a call, paired medians in one process;
// skipping, before the weight, the sources that no lane's taps reach from 2 lenses on: 0.96x again);
// on the frame's first and last lens, where clamping merged taps, it takes the taps as the forward does.
//
// No atomics: the adjoint is a gather, deterministic. With `squared` the adjoint writes diag(D^T D)
// ([H, W], one channel): the squared coefficients (the taps of one row on one lens summed first).
// `offsets` int [4, S, 2]: per lens row, (lo, hi) of the forward u, forward v, adjoint u, adjoint v
// offsets. Global size: (ceil(W / 16), H).
//
// The adjoint's order (run_at): its work-items take the rows view row by view row (u outer, lens row s inner), so
// that neighbouring work-items gather mostly the same source rows (s' + k, u' - 1) while those are in cache, and walk
// the frame in tiles of at most ADJOINT_TILE runs (1024 columns) of equal width, which keeps the 5 planes' rows they
// read in cache. At 500x500 lenses (charts, 2 lux, the default `lfcl process`, 3 bands, 132 calls) its time fell
// from 12.9 / 14.5 s to 10.7 / 10.2 s (runs alternating with the row-major order); at 128x128 lenses, where the rows
// fit the cache either way, whole solves did not move beyond the machine's noise (+-7 %). The forward, reordered
// alike, did not move at 500x500 lenses (7.8 / 8.3 against 8.0 / 7.5 s), so it keeps the row-major order.

#pragma OPENCL FP_CONTRACT OFF

#define MAX_CHANNELS 4

// The Catmull-Rom taps of p = own - d (lane-wise; own a whole lens index) at floor(p) - 1 .. floor(p) + 2 (Keys,
// a = -1/2), their lens indices clamped to [0, n - 1] (floats: small integers, exact), weights of the fraction
// f = p - floor(p). floor(p) = own + floor(-d) and f = -d - floor(-d) are exact in float32 whatever own is (the
// twin, lfcl/ops/epi.py lens_taps_np, computes them alike).
typedef struct { float16 i0, i1, i2, i3, w0, w1, w2, w3; } Taps;

inline Taps lens_taps(float16 own, float16 d, int n)
{
    Taps k;
    const float16 whole = floor(-d), base = own + whole, f = -d - whole, f2 = f * f, f3 = f2 * f;
    const float16 hi = (float16)(float)(n - 1);
    k.i0 = clamp(base - 1.0f, 0.0f, hi);
    k.i1 = clamp(base, 0.0f, hi);
    k.i2 = clamp(base + 1.0f, 0.0f, hi);
    k.i3 = clamp(base + 2.0f, 0.0f, hi);
    k.w0 = -0.5f * f3 + f2 - 0.5f * f;
    k.w1 = 1.5f * f3 - 2.5f * f2 + 1.0f;
    k.w2 = -1.5f * f3 + 2.0f * f2 + 0.5f * f;
    k.w3 = 0.5f * f3 - 0.5f * f2;
    return k;
}

// The Catmull-Rom weight at distance x >= 0 from the interpolated point (0 from 2 on): the weight that a ray
// with disparity d puts on the lens k lenses before its own, x = |d - k|, whenever no clamping merged taps there
// (any lens but the frame's first and last). The same kernel as lens_taps' weights up to float32 rounding.
inline float16 keys_at(float16 x)
{
    const float16 near = (1.5f * x - 2.5f) * x * x + 1.0f, far = ((-0.5f * x + 2.5f) * x - 4.0f) * x + 2.0f;
    return select(select((float16)0.0f, far, x < 2.0f), near, x <= 1.0f);
}

// Per lane: the summed weight of the taps that land on lens `target`.
inline float16 weight_on(const Taps *k, float16 target)
{
    const float16 zero = (float16)0.0f;
    return select(zero, k->w0, k->i0 == target) + select(zero, k->w1, k->i1 == target)
         + select(zero, k->w2, k->i2 == target) + select(zero, k->w3, k->i3 == target);
}

inline int any_nonzero(float16 v)
{
    return any(v != 0.0f);
}

// With `mix` (3 channels): the differences times I + C^T C, C the colour differences (R - G, B - G), so that
// D^T (mixed D x) is D^T D x + (D C)^T (D C) x, the EPI and cross-channel blocks' normal operator in one
// gather each way (lfcl/solvers/epi.py EpiAdmmSolver.normal; twin: lfcl/ops/epi.py epi_mixed_gradient_np).
inline void colour_mix(float16 *g)
{
    const float16 r = g[0], gr = g[1], b = g[2];
    g[0] = 2.0f * r - gr;
    g[1] = 3.0f * gr - r - b;
    g[2] = 2.0f * b - gr;
}

// The (first column, row) of this work-item's run: row-major ids (gid0 the run, gid1 the row) re-ordered as above,
// each row's runs cut into tiles of equal width (the last one narrower by what the division leaves).
#define ADJOINT_TILE 64

inline int2 run_at(int height)
{
    const int runs = get_global_size(0), S = height / PITCH_U, tiles = (runs + ADJOINT_TILE - 1) / ADJOINT_TILE;
    const int tile = (runs + tiles - 1) / tiles;
    const long id = (long)get_global_id(1) * runs + get_global_id(0), per_tile = (long)tile * height;
    const int first = (int)(id / per_tile) * tile, width = min(tile, runs - first);
    const int at = (int)(id - (long)first * height), r = at / width;
    return (int2)(16 * (first + at % width), (r % S) * PITCH_U + r / S);
}

// The adjoint's start on one run: acc holds out's values (accumulate) or 0 for its n channels, and w_u, w_v the
// sample's own rows' weights (its ray's w where it has a next sample in u, in v), which it takes with a minus sign.
inline void adjoint_start(float16 *acc, __global const float *x, __global const float *rays, size_t plane, size_t base,
                          int col0, int width, int n, int accumulate, int u1, int16 v_pos, float16 *w_u, float16 *w_v)
{
    for (int c = 0; c < n; ++c) acc[c] = accumulate ? load_row(x + c * plane + base, col0, 0, width) : (float16)0.0f;
    const float16 w_own = load_row(rays + plane + base, col0, 0, width);
    *w_u = u1 < PITCH_U - 1 ? w_own : (float16)0.0f;
    *w_v = select((float16)0.0f, w_own, v_pos < PITCH_V - 1);
}

// With EPI_IN_LENS (every disparity 0: the fall-back block and the in-lens cross block, lfcl/ops/epi.py
// EpiGradient.set_maps) each ray's neighbour is the next sample of its own lens, so the same two kernels are plain
// stencils: no taps, no offsets, no gathers over lens rows. The general kernels at d = 0 give the same numbers (the
// Catmull-Rom weight there is exactly 1 on the own lens and 0 elsewhere); these read a third of the rows.
#ifdef EPI_IN_LENS
__kernel void epi_forward(__global const float *x, __global float *z, __global const float *rays,
                          __global const int *offsets, const int height, const int width, const int channels,
                          const int mix)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1);
    if (col0 >= width || row >= height) return;
    const size_t plane = (size_t)height * width, base = (size_t)row * width;
    const int16 has_next = lane_columns(col0) % PITCH_V < PITCH_V - 1;
    const float16 w = load_row(rays + plane + base, col0, 0, width);
    float16 own[MAX_CHANNELS], acc[MAX_CHANNELS];
    for (int c = 0; c < channels; ++c) own[c] = load_row(x + c * plane + base, col0, 0, width);
    // u-block: the neighbour (s, t, u + 1, v), the next row
    for (int c = 0; c < channels; ++c) acc[c] = (float16)0.0f;
    if (row % PITCH_U < PITCH_U - 1) {
        for (int c = 0; c < channels; ++c) acc[c] = w * (load_row(x + c * plane + base + width, col0, 0, width) - own[c]);
        if (mix) colour_mix(acc);
    }
    for (int c = 0; c < channels; ++c) store_row(acc[c], z + c * plane + base, col0, width);
    // v-block: the neighbour (s, t, u, v + 1), the next column
    for (int c = 0; c < channels; ++c)
        acc[c] = select((float16)0.0f, w * (load_row(x + c * plane + base, col0, 1, width) - own[c]), has_next);
    if (mix) colour_mix(acc);
    for (int c = 0; c < channels; ++c) store_row(acc[c], z + (channels + c) * plane + base, col0, width);
}

__kernel void epi_adjoint(__global const float *z, __global float *x, __global const float *rays,
                          __global const int *offsets, const int height, const int width, const int channels,
                          const int accumulate, const int squared)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1);
    if (col0 >= width || row >= height) return;
    const size_t plane = (size_t)height * width, base = (size_t)row * width;
    const int n = squared ? 1 : channels, u1 = row % PITCH_U;
    __global const float *zu = z, *zv = z + (size_t)channels * plane;
    const int16 v_pos = lane_columns(col0) % PITCH_V;
    float16 acc[MAX_CHANNELS], w_u, w_v;
    adjoint_start(acc, x, rays, plane, base, col0, width, n, accumulate, u1, v_pos, &w_u, &w_v);
    // the rays whose neighbour it is: the previous row's (u > 0) and the previous column's (v > 0), +w each
    const float16 c_u = u1 > 0 ? load_row(rays + plane + base - width, col0, 0, width) : (float16)0.0f;
    const float16 c_v = select((float16)0.0f, load_row(rays + plane + base, col0, -1, width), v_pos > 0);
    if (squared) {
        acc[0] += w_u * w_u + w_v * w_v + c_u * c_u + c_v * c_v;
    } else {
        for (int c = 0; c < n; ++c) {
            acc[c] -= w_u * load_row(zu + c * plane + base, col0, 0, width)
                    + w_v * load_row(zv + c * plane + base, col0, 0, width);
            if (u1 > 0) acc[c] += c_u * load_row(zu + c * plane + base - width, col0, 0, width);
            acc[c] += c_v * load_row(zv + c * plane + base, col0, -1, width);
        }
    }
    for (int c = 0; c < n; ++c) store_row(acc[c], x + c * plane + base, col0, width);
}
#else
__kernel void epi_forward(__global const float *x, __global float *z, __global const float *rays,
                          __global const int *offsets, const int height, const int width, const int channels,
                          const int mix)
{
    const int col0 = 16 * get_global_id(0), row = get_global_id(1);
    if (col0 >= width || row >= height) return;
    const int S = height / PITCH_U, T = width / PITCH_V;
    const int s = row / PITCH_U, u = row % PITCH_U;
    const size_t plane = (size_t)height * width, base = (size_t)row * width;
    const int16 cols = lane_columns(col0);
    const float16 t = convert_float16(cols / PITCH_V);
    const float16 d = load_row(rays + base, col0, 0, width), w = load_row(rays + plane + base, col0, 0, width);
    float16 own[MAX_CHANNELS], acc[MAX_CHANNELS];
    for (int c = 0; c < channels; ++c) own[c] = load_row(x + c * plane + base, col0, 0, width);
    // u-block: the neighbour (s - d, t, u + 1, v), interpolated along s
    for (int c = 0; c < channels; ++c) acc[c] = (float16)0.0f;
    if (u < PITCH_U - 1) {
        const Taps k = lens_taps((float16)(float)s, d, S);
        for (int m = offsets[2 * s]; m <= offsets[2 * s + 1]; ++m) {
            const int lens = s + m;
            if (lens < 0 || lens >= S) continue;
            const float16 weight = weight_on(&k, (float16)(float)lens);
            if (!any_nonzero(weight)) continue;
            const size_t next = (size_t)(lens * PITCH_U + u + 1) * width;
            for (int c = 0; c < channels; ++c) acc[c] += weight * load_row(x + c * plane + next, col0, 0, width);
        }
        for (int c = 0; c < channels; ++c) acc[c] = w * (acc[c] - own[c]);
        if (mix) colour_mix(acc);
    }
    for (int c = 0; c < channels; ++c) store_row(acc[c], z + c * plane + base, col0, width);
    // v-block: the neighbour (s, t - d, u, v + 1), interpolated along t
    const int16 has_next = cols % PITCH_V < PITCH_V - 1;
    const Taps k = lens_taps(t, d, T);
    for (int c = 0; c < channels; ++c) acc[c] = (float16)0.0f;
    for (int m = offsets[2 * S + 2 * s]; m <= offsets[2 * S + 2 * s + 1]; ++m) {
        const float16 weight = select((float16)0.0f, weight_on(&k, t + (float)m), has_next);
        if (!any_nonzero(weight)) continue;
        for (int c = 0; c < channels; ++c)
            acc[c] += weight * load_row(x + c * plane + base, col0, m * PITCH_V + 1, width);
    }
    for (int c = 0; c < channels; ++c) acc[c] = select((float16)0.0f, w * (acc[c] - own[c]), has_next);
    if (mix) colour_mix(acc);
    for (int c = 0; c < channels; ++c) store_row(acc[c], z + (channels + c) * plane + base, col0, width);
}

// x (+)= D^T z, or with `squared` x (+)= diag(D^T D) (one [H, W] plane; z is not read).
__kernel void epi_adjoint(__global const float *z, __global float *x, __global const float *rays,
                          __global const int *offsets, const int height, const int width, const int channels,
                          const int accumulate, const int squared)
{
    const int2 run = run_at(height);
    const int col0 = run.x, row = run.y;
    if (col0 >= width || row >= height) return;
    const int S = height / PITCH_U, T = width / PITCH_V;
    const int s1 = row / PITCH_U, u1 = row % PITCH_U;
    const size_t plane = (size_t)height * width, base = (size_t)row * width;
    const int n = squared ? 1 : channels;
    __global const float *zu = z, *zv = z + (size_t)channels * plane;
    const int16 cols = lane_columns(col0);
    const float16 t1 = convert_float16(cols / PITCH_V);
    const int16 v_pos = cols % PITCH_V;
    float16 acc[MAX_CHANNELS], w_u, w_v;
    adjoint_start(acc, x, rays, plane, base, col0, width, n, accumulate, u1, v_pos, &w_u, &w_v);
    if (squared) {
        acc[0] += w_u * w_u + w_v * w_v;
    } else {
        for (int c = 0; c < n; ++c)
            acc[c] -= w_u * load_row(zu + c * plane + base, col0, 0, width)
                    + w_v * load_row(zv + c * plane + base, col0, 0, width);
    }
    // u-block rows (s1 + k, t, u1 - 1, v) whose taps along s land on s1 (the weight by distance, but on the
    // frame's first and last lens row, where clamping merged taps)
    if (u1 > 0) {
        const int edge = s1 == 0 || s1 == S - 1;
        for (int k = offsets[4 * S + 2 * s1]; k <= offsets[4 * S + 2 * s1 + 1]; ++k) {
            const int s = s1 + k;
            if (s < 0 || s >= S) continue;
            const size_t source = (size_t)(s * PITCH_U + u1 - 1) * width;
            const float16 d = load_row(rays + source, col0, 0, width);
            float16 weight;
            if (edge) {
                const Taps taps = lens_taps((float16)(float)s, d, S);
                weight = weight_on(&taps, (float16)(float)s1);
            } else {
                const float16 x = fabs(d - (float)k);
                if (!any(x < 2.0f)) continue;
                weight = keys_at(x);
            }
            const float16 coef = load_row(rays + plane + source, col0, 0, width) * weight;
            if (!any_nonzero(coef)) continue;
            if (squared)
                acc[0] += coef * coef;
            else
                for (int c = 0; c < n; ++c) acc[c] += coef * load_row(zu + c * plane + source, col0, 0, width);
        }
    }
    // v-block rows (s1, t1 + k, u1, v - 1) whose taps along t land on t1 (lanes with v > 0; by distance, but in
    // the runs that hold a lane of the frame's first or last lens column)
    const int edge = col0 < PITCH_V || col0 + 16 > width - PITCH_V;
    for (int k = offsets[6 * S + 2 * s1]; k <= offsets[6 * S + 2 * s1 + 1]; ++k) {
        const int shift = k * PITCH_V - 1;
        const float16 t = t1 + (float)k;
        const float16 d = load_row(rays + base, col0, shift, width);
        float16 weight;
        if (edge) {
            const Taps taps = lens_taps(t, d, T);
            weight = weight_on(&taps, t1);
        } else {
            const float16 x = fabs(d - (float)k);
            if (!any(x < 2.0f)) continue;
            weight = keys_at(x);
        }
        // outside the row the loaded weight is 0; sources past the frame (t >= T) have none either
        const float16 coef = select((float16)0.0f, load_row(rays + plane + base, col0, shift, width) * weight,
                                    (v_pos > 0) & (t < (float)T));
        if (!any_nonzero(coef)) continue;
        if (squared)
            acc[0] += coef * coef;
        else
            for (int c = 0; c < n; ++c) acc[c] += coef * load_row(zv + c * plane + base, col0, shift, width);
    }
    for (int c = 0; c < n; ++c) store_row(acc[c], x + c * plane + base, col0, width);
}

#endif

// --- the x-update of the EPI ADMM (lfcl/solvers/epi.py): the weighted data term, on runs of 16 columns ---
// `weight_runs` are the U x V data-term weights of one lens (repeating from lens to lens) as common.cl
// row_weights reads them; `pattern` the packed Bayer phase (lfcl.layout.packed_pattern).
// Global size: (ceil(W / 16), H).

// The lanes' data-term weight in colour plane c: w where the lane's pixel measured c, else 0 (diag(A^T W A)).
inline float16 data_weight(__global const float *weight_runs, int row, int16 cols, int pattern, int c)
{
    return select((float16)0.0f, row_weights(weight_runs, row, cols), measured_lanes(row, cols, pattern, c));
}

#define RUN_PROLOGUE                                                                                     \
    const int col0 = 16 * get_global_id(0), row = get_global_id(1);                                    \
    if (col0 >= width || row >= height) return;                                                        \
    const size_t plane = (size_t)height * width, base = (size_t)row * width;                           \
    const int16 cols = lane_columns(col0);

// The sum of the 16 lanes, pairwise.
inline float lane_sum(float16 v)
{
    const float8 a = v.lo + v.hi;
    const float4 b = a.lo + a.hi;
    const float2 c = b.lo + b.hi;
    return c.x + c.y;
}

// out = rho out + (A^T W A + delta) src  (out holding sum_b K_b^T K_b src; delta the proximal term of
// lfcl/solvers/epi.py EPI_PROXIMAL), and partial[work-item] = <src, out> over its 3 x 16 samples (CG's p.q; the host
// sums the partials, compensated: lfcl/ops/reduce.py sum).
__kernel void epi_normal_finish(__global float *out, __global const float *src, __global const float *weight_runs,
                                const float rho, const float delta, const int height, const int width,
                                const int pattern, __global float *partial)
{
    RUN_PROLOGUE
    float16 product = (float16)0.0f;
    for (int c = 0; c < 3; ++c) {
        const size_t at = c * plane + base;
        const float16 p = load_row(src + at, col0, 0, width);
        const float16 q = rho * load_row(out + at, col0, 0, width)
                        + (data_weight(weight_runs, row, cols, pattern, c) + delta) * p;
        store_row(q, out + at, col0, width);
        product += p * q;  // lanes past the row: 0 (load_row)
    }
    partial[(size_t)row * get_global_size(0) + get_global_id(0)] = lane_sum(product);
}

// The right-hand side and CG's first residual carried from one iteration to the next (lfcl/solvers/epi.py,
// EpiAdmmSolver.iterate has the algebra): with kz = K^T z, rhs = A^T W b + rho K^T (z - u) + delta x_prev and
// r = rhs - N x (N = A^T W A + rho K^T K + delta), after the z/u step (dual = K^T (z' - z), u' = u + K x - z'):
//   rhs' = r + A^T W A x + rho (kz + 2 dual) + delta (2 x - x_prev),   r' = rhs' - N x = rhs' - rhs + r,
//   kz' = kz + dual.
__kernel void epi_carry_rhs(__global float *rhs, __global float *r, __global float *kz, __global const float *dual,
                            __global const float *x, __global const float *x_prev, __global const float *weight_runs,
                            const float rho, const float delta, const int height, const int width, const int pattern)
{
    RUN_PROLOGUE
    for (int c = 0; c < 3; ++c) {
        const size_t at = c * plane + base;
        const float16 d = load_row(dual + at, col0, 0, width), ri = load_row(r + at, col0, 0, width);
        const float16 kz_next = load_row(kz + at, col0, 0, width) + d;
        const float16 xc = load_row(x + at, col0, 0, width);
        const float16 rhs_next = ri + data_weight(weight_runs, row, cols, pattern, c) * xc + rho * (kz_next + d)
                               + delta * (2.0f * xc - load_row(x_prev + at, col0, 0, width));
        store_row(rhs_next - load_row(rhs + at, col0, 0, width) + ri, r + at, col0, width);
        store_row(rhs_next, rhs + at, col0, width);
        store_row(kz_next, kz + at, col0, width);
    }
}

// out = rho out + A^T W b + delta x  (out holding sum_b K_b^T (z_b - u_b)): the right-hand side from its definition
// (EpiAdmmSolver.refresh; x the warm start of the next x-update).
__kernel void epi_rhs_finish(__global float *out, __global const float *b, __global const float *x,
                             __global const float *weight_runs, const float rho, const float delta, const int height,
                             const int width, const int pattern)
{
    RUN_PROLOGUE
    const float16 raw = load_row(b + base, col0, 0, width);
    for (int c = 0; c < 3; ++c) {
        const size_t at = c * plane + base;
        store_row(rho * load_row(out + at, col0, 0, width) + data_weight(weight_runs, row, cols, pattern, c) * raw
                  + delta * load_row(x + at, col0, 0, width), out + at, col0, width);
    }
}

// The preconditioner (block Jacobi): per pixel, the inverse of the 3x3 colour block of N = A^T W A + rho K^T K + delta,
//   [[m_R + a + b, -b, 0], [-b, m_G + a + 2 b, -b], [0, -b, m_B + a + b]],
// a = rho own + delta, own = diag(K^T K) [H, W] of the blocks that treat the colours alike, b = rho other, other =
// xdiag = diag(D^T D) of the cross-channel block, whose per-pixel block is C^T C times it ((D C)^T (D C) =
// C^T C (x) D^T D; 0 without it), m_c the data weight where the pixel measured colour c. The colour differences
// couple a pixel's colours as strongly as the lines couple its neighbours; the diagonal alone left CG's residual
// 1.7-2x higher after 5 steps (docs/admm.md, "The preconditioner"). Without the cross block (b = 0) it is the
// diagonal (Jacobi). A singular block (no prior and no delta: a diagonal only where the pixel measured) gives 0.
inline void block_jacobi(float16 own, float16 other, __global const float *weight_runs, int row, int16 cols,
                         int pattern, float rho, float delta, float16 *z0, float16 *z1, float16 *z2)
{
    const float16 a = rho * own + delta, b = rho * other;
    const float16 d0 = data_weight(weight_runs, row, cols, pattern, 0) + a + b;
    const float16 d1 = data_weight(weight_runs, row, cols, pattern, 1) + a + 2.0f * b;
    const float16 d2 = data_weight(weight_runs, row, cols, pattern, 2) + a + b;
    const float16 bb = b * b;
    const float16 det = d0 * d1 * d2 - bb * (d0 + d2);
    const float16 inv = select((float16)0.0f, 1.0f / det, det > 0.0f && d0 > 0.0f && d2 > 0.0f);
    const float16 r0 = *z0, r1 = *z1, r2 = *z2;
    *z0 = inv * ((d1 * d2 - bb) * r0 + b * d2 * r1 + bb * r2);
    *z1 = inv * (b * d2 * r0 + d0 * d2 * r1 + b * d0 * r2);
    *z2 = inv * (bb * r0 + b * d0 * r1 + (d0 * d1 - bb) * r2);
}

// out = the preconditioner applied to r (block_jacobi).
__kernel void epi_jacobi(__global const float *r, __global float *out, __global const float *kdiag,
                         __global const float *xdiag, const int cross, __global const float *weight_runs,
                         const float rho, const float delta, const int height, const int width, const int pattern)
{
    RUN_PROLOGUE
    const float16 own = load_row(kdiag + base, col0, 0, width);
    const float16 other = cross ? load_row(xdiag + base, col0, 0, width) : (float16)0.0f;
    float16 z0 = load_row(r + base, col0, 0, width), z1 = load_row(r + plane + base, col0, 0, width);
    float16 z2 = load_row(r + 2 * plane + base, col0, 0, width);
    block_jacobi(own, other, weight_runs, row, cols, pattern, rho, delta, &z0, &z1, &z2);
    store_row(z0, out + base, col0, width);
    store_row(z1, out + plane + base, col0, width);
    store_row(z2, out + 2 * plane + base, col0, width);
}

// One CG step's vector work in one pass: x += alpha p, r -= alpha q, pz = r / diag (epi_jacobi), and per work-item
// the partial sums of <r, pz> and |r|^2 (the host sums them, compensated: lfcl/solvers/cg.py).
__kernel void epi_cg_update(__global float *x, __global const float *p, __global float *r, __global const float *q,
                            __global float *pz, const float alpha, __global const float *kdiag,
                            __global const float *xdiag, const int cross, __global const float *weight_runs,
                            const float rho, const float delta, const int height, const int width,
                            const int pattern, __global float *rz_partial, __global float *r2_partial)
{
    RUN_PROLOGUE
    const float16 own = load_row(kdiag + base, col0, 0, width);
    const float16 other = cross ? load_row(xdiag + base, col0, 0, width) : (float16)0.0f;
    float16 rc[3], zc[3];
    for (int c = 0; c < 3; ++c) {
        const size_t at = c * plane + base;
        const float16 pc = load_row(p + at, col0, 0, width);
        store_row(load_row(x + at, col0, 0, width) + alpha * pc, x + at, col0, width);
        rc[c] = load_row(r + at, col0, 0, width) - alpha * load_row(q + at, col0, 0, width);
        store_row(rc[c], r + at, col0, width);
        zc[c] = rc[c];
    }
    block_jacobi(own, other, weight_runs, row, cols, pattern, rho, delta, &zc[0], &zc[1], &zc[2]);
    float16 rz = (float16)0.0f, r2 = (float16)0.0f;
    for (int c = 0; c < 3; ++c) {
        store_row(zc[c], pz + c * plane + base, col0, width);
        rz += rc[c] * zc[c];  // lanes past the row: 0 (load_row)
        r2 += rc[c] * rc[c];
    }
    const size_t w = (size_t)row * get_global_size(0) + get_global_id(0);
    rz_partial[w] = lane_sum(rz);
    r2_partial[w] = lane_sum(r2);
}

// partial[row] = sum over the row of w (x[colour] - b)^2 (Kahan-compensated). Global size: (H).
__kernel void epi_misfit_rows(__global const float *x, __global const float *b, __global const float *weight_runs,
                              __global float *partial, const int height, const int width, const int pattern)
{
    const int row = get_global_id(0);
    if (row >= height) return;
    const size_t plane = (size_t)height * width, base = (size_t)row * width;
    float sum = 0.0f, err = 0.0f;
    for (int col = 0; col < width; ++col) {
        const float r = x[bayer_colour(row, col, pattern) * plane + base + col] - b[base + col];
        const float term = weight_runs[((row % PITCH_U) * PITCH_V + col % PITCH_V) * 16] * r * r - err;
        const float next = sum + term;
        err = (next - sum) - term;
        sum = next;
    }
    partial[row] = sum;
}

// The z/u step of one prior block, in place, chunks of 16 floats (shrink.cl's layout):
//   v = kx + u, z' = S_kappa(v), u' = v - z', kx <- z' - z (dz, for the dual residual),
// with the chunk sums of the primal residual (kx - z')^2 in primal[k] and of |kx| in l1[k].
__kernel void epi_zu(__global float *kx, __global float *z, __global float *u, __global float *primal,
                     __global float *l1, const float kappa, const ulong n, const ulong chunks)
{
    const ulong k = get_global_id(0);
    if (k >= chunks) return;
    const float16 dx = load_chunk(kx, k, n);
    const float16 v = dx + load_chunk(u, k, n);
    const float16 m = fabs(v) - kappa;
    const float16 z_new = copysign(select(m, (float16)0.0f, m < 0.0f), v);
    const float16 z_old = load_chunk(z, k, n);
    store_chunk(z_new, z, k, n);
    store_chunk(v - z_new, u, k, n);
    store_chunk(z_new - z_old, kx, k, n);
    const float16 r = dx - z_new, r2 = r * r, a = fabs(dx);  // the padding lanes are 0 in both
    primal[k] = ((r2.s0 + r2.s1) + (r2.s2 + r2.s3)) + ((r2.s4 + r2.s5) + (r2.s6 + r2.s7))
              + ((r2.s8 + r2.s9) + (r2.sa + r2.sb)) + ((r2.sc + r2.sd) + (r2.se + r2.sf));
    l1[k] = ((a.s0 + a.s1) + (a.s2 + a.s3)) + ((a.s4 + a.s5) + (a.s6 + a.s7))
          + ((a.s8 + a.s9) + (a.sa + a.sb)) + ((a.sc + a.sd) + (a.se + a.sf));
}

// CG's warm start extrapolated along the last x-update, in place, chunks of 16 floats (twin: lfcl/solvers/epi.py
// epi_extrapolate_np). On entry x = x_k, x_prev = x_{k-1}, r = rhs - N x_k (carried), dnx = N x_k - N x_{k-1}; after:
//   x_prev = x_k (the x-update's anchor), x = x_k + beta (x_k - x_{k-1}), r = r - beta dnx = rhs - N x,
//   dnx = beta dnx + r,
// so that once CG has brought r to its final rhs - N x_{k+1}, dnx - r is N x_{k+1} - N x_k (EpiAdmmSolver.iterate).
__kernel void epi_extrapolate(__global float *x, __global float *x_prev, __global float *r, __global float *dnx,
                              const float beta, const ulong n, const ulong chunks)
{
    const ulong k = get_global_id(0);
    if (k >= chunks) return;
    const float16 xk = load_chunk(x, k, n), older = load_chunk(x_prev, k, n), d = load_chunk(dnx, k, n);
    const float16 rn = load_chunk(r, k, n) - beta * d;
    store_chunk(xk, x_prev, k, n);
    store_chunk(xk + beta * (xk - older), x, k, n);
    store_chunk(rn, r, k, n);
    store_chunk(beta * d + rn, dnx, k, n);
}

// The rays' maps from the lens maps (twin: lfcl/ops/epi.py ray_maps_np): sample (s, t, u, v) reads the disparity and
// the confidence at the lens its ray sees in the centre view, round(s + d0 (u - uc)), round(t + d0 (v - vc)) (d0
// its own lens's disparity), clamped to the frame, in float32 without contraction as the twin computes it.
// rays [2, H, W]. Global size (W, H).
__kernel void epi_ray_maps(__global const float *disparity, __global const float *confidence, __global float *rays,
                           const int S, const int T)
{
    const int col = get_global_id(0), row = get_global_id(1);
    const int W = T * PITCH_V, H = S * PITCH_U;
    if (col >= W || row >= H)
        return;
    const int s = row / PITCH_U, u = row - s * PITCH_U, t = col / PITCH_V, v = col - t * PITCH_V;
    const float d0 = disparity[s * T + t];
    const float ku = (float)u - 0.5f * (float)(PITCH_U - 1), kv = (float)v - 0.5f * (float)(PITCH_V - 1);
    const float ys = (float)s + d0 * ku, xs = (float)t + d0 * kv;
    const int sc = clamp((int)floor(ys + 0.5f), 0, S - 1), tc = clamp((int)floor(xs + 0.5f), 0, T - 1);
    rays[(size_t)row * W + col] = disparity[sc * T + tc];
    rays[(size_t)H * W + (size_t)row * W + col] = confidence[sc * T + tc];
}

// Per lens, the offsets (relative to the lens) of the first and last lens that a tap of nonzero weight of any of its
// rays lands on, before clamping to the frame (twin: lfcl/ops/epi.py lens_tap_spans_np): spans [4, S, T] int of
// (u-block first, u-block last, v-block first, v-block last); the u-block takes the rows u < U - 1, the v-block the
// columns v < V - 1 (first > last when there are none). p = own - d: floor(p) = own + floor(-d); the taps are
// floor(p) - 1 .. floor(p) + 2, only floor(p) when p is whole. The host builds the kernels' offset table from them.
// Global size (T, S).
__kernel void epi_lens_tap_spans(__global const float *rays, __global int *spans, const int S, const int T)
{
    const int t = get_global_id(0), s = get_global_id(1);
    if (t >= T || s >= S)
        return;
    const int W = T * PITCH_V;
    int u_lo = 1 << 20, u_hi = -(1 << 20), v_lo = 1 << 20, v_hi = -(1 << 20);
    for (int u = 0; u < PITCH_U; ++u)
        for (int v = 0; v < PITCH_V; ++v) {
            const float d = rays[(size_t)(s * PITCH_U + u) * W + t * PITCH_V + v];
            const float whole = floor(-d);
            const int exact = (-d - whole) == 0.0f;
            const int lo = (int)whole - (exact ? 0 : 1), hi = (int)whole + (exact ? 0 : 2);
            if (u < PITCH_U - 1) {
                u_lo = min(u_lo, lo);
                u_hi = max(u_hi, hi);
            }
            if (v < PITCH_V - 1) {
                v_lo = min(v_lo, lo);
                v_hi = max(v_hi, hi);
            }
        }
    const size_t plane = (size_t)S * T, at = (size_t)s * T + t;
    spans[at] = u_lo;
    spans[plane + at] = u_hi;
    spans[2 * plane + at] = v_lo;
    spans[3 * plane + at] = v_hi;
}
