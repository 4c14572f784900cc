// Photo-consistency cost volume for disparity from a lenslet mosaic (lfcl/depth/cost.py has the
// derivation and the numpy twin cost_volume_np).
//
// One work-item per (listed lens, candidate k). For every view (u, v) the centre-view lens
// (s, t) is seen at the fractional lens (y, x) = (s - d (u - uc), t - d (v - vc)); the raw samples
// of view (u, v) in the four lenses around it are gathered with bilinear weights, each under its
// own CFA colour, at centre-view offset p = (s' - y, t' - x). Per colour: weighted sums for a
// least-squares plane a + g.p (ridge RIDGE * W on g; PLANE_MODEL=0: the mean only), then
//   excess = sum_c RSS_c / nv_c - (W_c - tr((A_c + R_c)^-1 B_c)),   weight = sum_c W_c.
// Values are taken relative to the lens's own centre pixel (conditioning in float32 only).
// With eta > 0 the excess also holds eta times the colour penalty (lfcl/depth/cost.py, "The colour penalty"):
// how far the candidate's per-colour means lie from the span of grey and the lens's own colour
// (colour[4][S][T] from depth_lens_colour), in noise units, less its noise-only expectation. With bound_clipped
// (depth_cost; no lens of depth_cost_interior reaches a clipped sample) a colour's clipped samples bound its fit from
// below (lfcl/depth/cost.py, "Clipped samples").
//
// Build-time constants: PITCH_U, PITCH_V, PLANE_MODEL (0/1), RIDGE_PPM and MIN_WEIGHT_PPM (the
// ridge factor and the smallest colour weight kept, in millionths), HALVES (0/1).
// Without HALVES only the views u_lo <= u <= u_hi, v_lo <= v <= v_hi are gathered (a half aperture sees
// past an occluder that the other half runs into).
// Output: cost[a][0][k][s][t] = excess, cost[a][1][k][s][t] = weight of aperture a (one, or five with
// HALVES). Global size (count, ND) over the listed lenses (s T + t); depth_cost_interior gathers a
// box of the others faster, and CostVolume lists the rest here.

#define RIDGE (RIDGE_PPM * 1e-6f)
#define MIN_WEIGHT (MIN_WEIGHT_PPM * 1e-6f)
#define NSUM 16
// HALVES=1: one gather for the full aperture and the four half apertures (top u <= U/2, bottom
// u >= U - 1 - U/2, left v <= V/2, right v >= V - 1 - V/2; lfcl.depth.cost.half_apertures). The views
// fall into 3x3 regions (rows above / in / below the shared centre rows, likewise columns); each
// region's sums are gathered once and added to every aperture that holds it, instead of gathering
// the shared views once per aperture (81 + 4 x 45 gathers of 9x9 views).
#if HALVES
#define NSUB 5
#define NREG 3
#else
#define NSUB 1
#define NREG 1
#endif

// The views of region r (0..NREG-1) along one axis of n views, clipped to [lo, hi].
inline int2 region_views(const int r, const int n, const int lo, const int hi)
{
#if HALVES
    const int mid = n / 2;
    const int first = r == 0 ? 0 : (r == 1 ? n - 1 - mid : mid + 1);
    const int last = r == 0 ? n - 2 - mid : (r == 1 ? mid : n - 1);
    return (int2)(max(first, lo), min(last, hi));
#else
    return (int2)(max(lo, 0), min(hi, n - 1));
#endif
}

// The colour penalty of one aperture (lfcl.depth.cost.colour_penalty_np): the kept colours' means m (less ref),
// their weights k = W / nv, the lens's own colour r (less ref) and its kind (0 grey, 1 coloured, 2 unknown).
inline float colour_penalty(const float m[3], const float k[3], const float r[3], const float kind)
{
    float K = 0.0f, km = 0.0f, kr = 0.0f;
    int n = 0;
    for (int c = 0; c < 3; ++c)
        if (k[c] > 0.0f) {
            K += k[c];
            km += k[c] * m[c];
            kr += k[c] * r[c];
            ++n;
        }
    if (n < 2 || !(kind < 1.5f))
        return 0.0f;
    const float mbar = km / K, rbar = kr / K;
    float mr = 0.0f, rr = 0.0f;
    for (int c = 0; c < 3; ++c)
        if (k[c] > 0.0f) {
            mr += k[c] * (m[c] - mbar) * (r[c] - rbar);
            rr += k[c] * (r[c] - rbar) * (r[c] - rbar);
        }
    const int fit = kind > 0.5f && rr > 0.0f;
    const float alpha = fit ? fmax(mr / rr, 0.0f) : 0.0f;  // a multiple of the lens's colour, not of its inverse
    float penalty = 0.0f;
    for (int c = 0; c < 3; ++c)
        if (k[c] > 0.0f) {
            const float e = (m[c] - mbar) - alpha * (r[c] - rbar);
            penalty += k[c] * e * e;
        }
    return penalty - (float)(n - 1 - fit);
}

// excess and weight of one aperture's per-colour sums (values less ref); eta > 0 adds the colour penalty against
// the lens's colour `lens` (r_R, r_G, r_B, kind; absolute values).
inline float2 aperture_cost(float acc[3][NSUM], const float ref, const float gain, const float floor_var,
                            const float eta, const float4 lens, const float clipped[3][3], const float saturation)
{
    float excess = 0.0f, weight = 0.0f;
    float m[3] = {0.0f, 0.0f, 0.0f}, k[3] = {0.0f, 0.0f, 0.0f};
    for (int c = 0; c < 3; ++c) {
        const float Wc = acc[c][0];
        if (!(Wc >= MIN_WEIGHT))
            continue;
        const float mean = acc[c][6] / Wc + ref;  // the sums are of values less ref
        const float nv = fmax(gain * fmax(mean, 0.0f) + floor_var, 1e-12f);
        m[c] = acc[c][6] / Wc;
        k[c] = Wc / nv;
        float rss, trace, fit = mean;  // fit: the colour's fitted value at its clipped samples' mean place
#if PLANE_MODEL
        const float r = RIDGE * Wc;
        // A = [[W, Sy, Sx], [Sy, Syy + r, Syx], [Sx, Syx, Sxx + r]] (symmetric): inverse by cofactors.
        const float a00 = Wc, a01 = acc[c][1], a02 = acc[c][2];
        const float a11 = acc[c][3] + r, a12 = acc[c][5], a22 = acc[c][4] + r;
        const float c00 = a11 * a22 - a12 * a12;
        const float c01 = a02 * a12 - a01 * a22;
        const float c02 = a01 * a12 - a02 * a11;
        const float c11 = a00 * a22 - a02 * a02;
        const float c12 = a01 * a02 - a00 * a12;
        const float c22 = a00 * a11 - a01 * a01;
        const float inv_det = 1.0f / (a00 * c00 + a01 * c01 + a02 * c02);
        const float i00 = c00 * inv_det, i01 = c01 * inv_det, i02 = c02 * inv_det;
        const float i11 = c11 * inv_det, i12 = c12 * inv_det, i22 = c22 * inv_det;
        const float b0 = acc[c][6], b1 = acc[c][7], b2 = acc[c][8];
        rss = acc[c][9] - (b0 * (i00 * b0 + i01 * b1 + i02 * b2) + b1 * (i01 * b0 + i11 * b1 + i12 * b2)
                           + b2 * (i02 * b0 + i12 * b1 + i22 * b2));
        // tr(Ainv B), B = [[Q, Qy, Qx], [Qy, Qyy, Qyx], [Qx, Qyx, Qxx]] (both symmetric).
        const float q00 = acc[c][10], q01 = acc[c][11], q02 = acc[c][12];
        const float q11 = acc[c][13], q12 = acc[c][15], q22 = acc[c][14];
        trace = i00 * q00 + i11 * q11 + i22 * q22 + 2.0f * (i01 * q01 + i02 * q02 + i12 * q12);
        if (clipped[c][0] > 0.0f)
            fit = ref + (i00 * b0 + i01 * b1 + i02 * b2)
                  + (i01 * b0 + i11 * b1 + i12 * b2) * clipped[c][1] / clipped[c][0]
                  + (i02 * b0 + i12 * b1 + i22 * b2) * clipped[c][2] / clipped[c][0];
#else
        rss = acc[c][9] - acc[c][6] * acc[c][6] / Wc;
        trace = acc[c][10] / Wc;
#endif
        excess += rss / nv - (Wc - trace);
        weight += Wc;
        // The clipped samples of this colour bound its radiance from below (lfcl/depth/cost.py, "Clipped samples").
        if (clipped[c][0] > 0.0f) {
            const float nv_clip = fmax(gain * fmax(saturation, 0.0f) + floor_var, 1e-12f);
            const float gap = fmax(saturation - fit - sqrt(nv_clip), 0.0f);
            excess += clipped[c][0] * gap * gap / nv_clip;
        }
    }
    if (eta > 0.0f) {
        const float r[3] = {lens.x - ref, lens.y - ref, lens.z - ref};
        excess += eta * colour_penalty(m, k, r, lens.w);
    }
    return (float2)(excess, weight);
}

// The lens's colour for the penalty: [4][S][T] = the means of its own unsaturated samples per colour, then its kind:
// 2 (unknown) if a colour has no such sample, else 1 (coloured) if the means differ from one grey by more than
// chi2 (their chi-square in noise units, the variance of a mean nv / n), else 0. Global size (T, S).
__kernel void depth_lens_colour(__global const float *mosaic, __global float *colour, const int S, const int T,
                                const int pattern, const float gain, const float floor_var, const float saturation,
                                const float chi2)
{
    const int t = get_global_id(0), s = get_global_id(1);
    if (t >= T || s >= S)
        return;
    float sum[3] = {0.0f, 0.0f, 0.0f};
    int n[3] = {0, 0, 0};
    for (int u = 0; u < PITCH_U; ++u)
        for (int v = 0; v < PITCH_V; ++v) {
            const int row = s * PITCH_U + u, col = t * PITCH_V + v;
            const float raw = mosaic[(size_t)row * T * PITCH_V + col];
            if (!(raw < saturation))
                continue;
            const int c = bayer_colour(row, col, pattern);
            sum[c] += raw;
            n[c] += 1;
        }
    const size_t plane = (size_t)S * T, at = (size_t)s * T + t;
    float mean[3], w[3], W = 0.0f, wm = 0.0f;
    for (int c = 0; c < 3; ++c) {
        mean[c] = n[c] > 0 ? sum[c] / (float)n[c] : 0.0f;
        w[c] = (float)n[c] / fmax(gain * fmax(mean[c], 0.0f) + floor_var, 1e-12f);
        W += w[c];
        wm += w[c] * mean[c];
        colour[c * plane + at] = mean[c];
    }
    float chi = 0.0f;
    for (int c = 0; c < 3; ++c)
        chi += w[c] * (mean[c] - wm / W) * (mean[c] - wm / W);
    colour[3 * plane + at] = (n[0] == 0 || n[1] == 0 || n[2] == 0) ? 2.0f : (chi > chi2 ? 1.0f : 0.0f);
}

__kernel void depth_cost(__global const float *mosaic, __constant float *disparities, __global const int *lenses,
                         __global float *cost, const int count, const int S, const int T, const int ND,
                         const int pattern, const float gain, const float floor_var, const float saturation,
                         const int u_lo, const int u_hi, const int v_lo, const int v_hi,
                         __global const float *colour, const float eta, const int bound_clipped)
{
    const int i = get_global_id(0);
    const int k = get_global_id(1);
    if (i >= count || k >= ND)  // the global size is rounded up to whole work-groups (see depth_cost_interior)
        return;
    const int s = lenses[i] / T;
    const int t = lenses[i] - s * T;
    const int W = T * PITCH_V;
    const float d = disparities[k];
    const float uc = 0.5f * (float)(PITCH_U - 1);
    const float vc = 0.5f * (float)(PITCH_V - 1);
    const float ref = mosaic[(s * PITCH_U + PITCH_U / 2) * W + t * PITCH_V + PITCH_V / 2];

    float total[NSUB][3][NSUM];
    float clipped[NSUB][3][3];  // per colour, the clipped samples gathered: sum w, sum w p_y, sum w p_x
    for (int a = 0; a < NSUB; ++a)
        for (int c = 0; c < 3; ++c) {
            clipped[a][c][0] = clipped[a][c][1] = clipped[a][c][2] = 0.0f;
            for (int j = 0; j < NSUM; ++j)
                total[a][c][j] = 0.0f;
        }

    for (int ry = 0; ry < NREG; ++ry) {
        const int2 us = region_views(ry, PITCH_U, u_lo, u_hi);
        for (int rx = 0; rx < NREG; ++rx) {
            const int2 vs = region_views(rx, PITCH_V, v_lo, v_hi);
            float acc[3][NSUM];
            float clip[3][3] = {{0.0f, 0.0f, 0.0f}, {0.0f, 0.0f, 0.0f}, {0.0f, 0.0f, 0.0f}};
            for (int c = 0; c < 3; ++c)
                for (int j = 0; j < NSUM; ++j)
                    acc[c][j] = 0.0f;
            for (int u = us.x; u <= us.y; ++u) {
                const float oy = -d * ((float)u - uc);  // the taps' floor and fraction, exact in float32
                const float y0 = (float)s + floor(oy);
                const float fy = oy - floor(oy);
                for (int v = vs.x; v <= vs.y; ++v) {
                    const float ox = -d * ((float)v - vc);
                    const float x0 = (float)t + floor(ox);
                    const float fx = ox - floor(ox);
                    for (int a = 0; a < 2; ++a) {
                        const int sp = (int)y0 + a;
                        const float wy = a ? fy : 1.0f - fy;
                        if (sp < 0 || sp >= S || !(wy > 0.0f))
                            continue;
                        const float py = (float)a - fy;
                        const int row = sp * PITCH_U + u;
                        for (int b = 0; b < 2; ++b) {
                            const int tp = (int)x0 + b;
                            const float wx = b ? fx : 1.0f - fx;
                            if (tp < 0 || tp >= T || !(wx > 0.0f))
                                continue;
                            const float px = (float)b - fx;
                            const int col = tp * PITCH_V + v;
                            const float raw = mosaic[row * W + col];
                            const float w = wy * wx;
                            const int c = bayer_colour(row, col, pattern);
                            if (bound_clipped && raw >= saturation) {
                                clip[c][0] += w;
                                clip[c][1] += w * py;
                                clip[c][2] += w * px;
                            }
                            if (!(raw < saturation))
                                continue;
                            const float value = raw - ref;
                            const float w2 = w * w;
                            acc[c][0] += w;
                            acc[c][1] += w * py;
                            acc[c][2] += w * px;
                            acc[c][3] += w * py * py;
                            acc[c][4] += w * px * px;
                            acc[c][5] += w * py * px;
                            acc[c][6] += w * value;
                            acc[c][7] += w * value * py;
                            acc[c][8] += w * value * px;
                            acc[c][9] += w * value * value;
                            acc[c][10] += w2;
                            acc[c][11] += w2 * py;
                            acc[c][12] += w2 * px;
                            acc[c][13] += w2 * py * py;
                            acc[c][14] += w2 * px * px;
                            acc[c][15] += w2 * py * px;
                        }
                    }
                }
            }
            // The apertures that hold this region: the full one, and (HALVES) top, bottom, left, right.
            for (int a = 0; a < NSUB; ++a) {
                const bool holds = a == 0 || (a == 1 && ry <= 1) || (a == 2 && ry >= 1) || (a == 3 && rx <= 1)
                                   || (a == 4 && rx >= 1);
                if (holds)
                    for (int c = 0; c < 3; ++c) {
                        for (int j = 0; j < 3; ++j)
                            clipped[a][c][j] += clip[c][j];
                        for (int j = 0; j < NSUM; ++j)
                            total[a][c][j] += acc[c][j];
                    }
            }
        }
    }

    const size_t plane = (size_t)S * T;
    const size_t at = (size_t)s * T + t;
    const float4 lens = eta > 0.0f ? (float4)(colour[at], colour[plane + at], colour[2 * plane + at],
                                              colour[3 * plane + at]) : (float4)(0.0f);
    for (int a = 0; a < NSUB; ++a) {
        const float2 ew = aperture_cost(total[a], ref, gain, floor_var, eta, lens, clipped[a], saturation);
        cost[((size_t)a * 2 * ND + k) * plane + s * T + t] = ew.x;
        cost[((size_t)a * 2 * ND + ND + k) * plane + s * T + t] = ew.y;
    }
}


// The interior fast path of depth_cost (lfcl.depth.cost.CostVolume): COST_LANES (8) lenses along t per work-item,
// on the view-major copy of the mosaic (depth_views), so that one tap of the 8 lenses is one vector load (the
// kernels here are scalar per work-item on a CPU; the vector types are what fills its SIMD lanes).
// For a lens whose every tap lies inside the frame and is unsaturated, the sums that depend only on the taps'
// places and weights (W, the p and p p^T moments and their w^2 twins: 12 of the 16 per colour) are the same for
// every lens of the same row and column parity: the host tabulates them (`geometry`: [ND][NSUB][4 parities]
// [3 colours][12], CostVolume's _geometry) and the kernel gathers only the 4 value sums per colour (w x, w x p_y,
// w x p_x, w x^2), each colour by a lane mask. Global size ((t_hi - t_lo) / COST_LANES, s_hi - s_lo, ND) over a box
// of such lenses, rounded up to whole work-groups of a size the host sets: a work-item holds ~2.5 KB of private
// arrays, and PoCL, left to choose, made work-groups of ~4000 work-items whose private memory overflowed its
// thread's stack (a crash at 200x200 lenses). CostVolume lists the others for depth_cost.
#define COST_LANES 8
__kernel void depth_cost_interior(__global const float *views, __constant float *disparities,
                                  __global const float *geometry, __global float *cost,
                                  const int S, const int T, const int ND, const int pattern,
                                  const float gain, const float floor_var, const int s_lo, const int t_lo,
                                  const int s_hi, const int t_hi, const int u_lo, const int u_hi, const int v_lo,
                                  const int v_hi, __global const float *colour, const float eta)
{
    const int t0 = t_lo + COST_LANES * get_global_id(0);
    const int s = s_lo + get_global_id(1);
    const int k = get_global_id(2);
    if (t0 + COST_LANES > t_hi || s >= s_hi || k >= ND)  // the global size is rounded up to whole work-groups
        return;
    const size_t plane = (size_t)S * T;
    const size_t lens = (size_t)s * T + t0;
    const float d = disparities[k];
    const float uc = 0.5f * (float)(PITCH_U - 1);
    const float vc = 0.5f * (float)(PITCH_V - 1);
    const float8 ref = vload8(0, views + (size_t)((PITCH_U / 2) * PITCH_V + PITCH_V / 2) * plane + lens);
    // Lane j's column parity is lane 0's, flipped on odd lanes when the pitch is odd.
    const int8 lane_flip = (int8)(0, 1, 0, 1, 0, 1, 0, 1) * (PITCH_V & 1);

    float8 value[NSUB][3][4];
    for (int a = 0; a < NSUB; ++a)
        for (int c = 0; c < 3; ++c)
            for (int j = 0; j < 4; ++j)
                value[a][c][j] = (float8)(0.0f);

    for (int ry = 0; ry < NREG; ++ry) {
        const int2 us = region_views(ry, PITCH_U, u_lo, u_hi);
        for (int rx = 0; rx < NREG; ++rx) {
            const int2 vs = region_views(rx, PITCH_V, v_lo, v_hi);
            float8 acc[3][4];
            for (int c = 0; c < 3; ++c)
                for (int j = 0; j < 4; ++j)
                    acc[c][j] = (float8)(0.0f);
            for (int u = us.x; u <= us.y; ++u) {
                const float oy = -d * ((float)u - uc);
                const float fy = oy - floor(oy);
                const int sp = s + (int)floor(oy);
                for (int v = vs.x; v <= vs.y; ++v) {
                    const float ox = -d * ((float)v - vc);
                    const float fx = ox - floor(ox);
                    const int tp = t0 + (int)floor(ox);
                    __global const float *view = views + (size_t)(u * PITCH_V + v) * plane;
                    for (int a = 0; a < 2; ++a) {
                        const float wy = a ? fy : 1.0f - fy;
                        const float py = (float)a - fy;
                        const int row_parity = ((sp + a) * PITCH_U + u) & 1;
                        for (int b = 0; b < 2; ++b) {
                            const float wx = b ? fx : 1.0f - fx;
                            const float px = (float)b - fx;
                            const float8 x = vload8(0, view + (size_t)(sp + a) * T + tp + b) - ref;
                            const float8 wxv = (wy * wx) * x;
                            const int8 col_parity = (int8)(((tp + b) * PITCH_V + v) & 1) ^ lane_flip;
                            const int8 colour = ((int8)(pattern) >> (2 * ((row_parity << 1) | col_parity))) & 3;
                            for (int c = 0; c < 3; ++c) {
                                const float8 m = select((float8)(0.0f), wxv, colour == c);
                                acc[c][0] += m;
                                acc[c][1] += m * py;
                                acc[c][2] += m * px;
                                acc[c][3] += m * x;
                            }
                        }
                    }
                }
            }
            for (int a = 0; a < NSUB; ++a) {
                const bool holds = a == 0 || (a == 1 && ry <= 1) || (a == 2 && ry >= 1) || (a == 3 && rx <= 1)
                                   || (a == 4 && rx >= 1);
                if (holds)
                    for (int c = 0; c < 3; ++c)
                        for (int j = 0; j < 4; ++j)
                            value[a][c][j] += acc[c][j];
            }
        }
    }

    float refs[COST_LANES];
    vstore8(ref, 0, refs);
    for (int a = 0; a < NSUB; ++a) {
        float sums[3][4][COST_LANES];
        for (int c = 0; c < 3; ++c)
            for (int j = 0; j < 4; ++j)
                vstore8(value[a][c][j], 0, sums[c][j]);
        for (int lane = 0; lane < COST_LANES; ++lane) {
            const int parity = ((s & 1) << 1) | ((t0 + lane) & 1);
            __global const float *g = geometry + (((size_t)k * NSUB + a) * 4 + parity) * 3 * 12;
            float total[3][NSUM];
            for (int c = 0; c < 3; ++c) {
                for (int j = 0; j < 6; ++j) {
                    total[c][j] = g[c * 12 + j];
                    total[c][10 + j] = g[c * 12 + 6 + j];
                }
                for (int j = 0; j < 4; ++j)
                    total[c][6 + j] = sums[c][j][lane];
            }
            const size_t at = lens + lane;
            const float4 own = eta > 0.0f ? (float4)(colour[at], colour[plane + at], colour[2 * plane + at],
                                                     colour[3 * plane + at]) : (float4)(0.0f);
            const float none[3][3] = {{0.0f}};  // no clipped sample reaches a lens of this box
            const float2 ew = aperture_cost(total, refs[lane], gain, floor_var, eta, own, none, 1.0f);
            cost[((size_t)a * 2 * ND + k) * plane + lens + lane] = ew.x;
            cost[((size_t)a * 2 * ND + ND + k) * plane + lens + lane] = ew.y;
        }
    }
}

// The view-major copy of an [S*U, T*V] mosaic for depth_cost_interior: views[u][v][s][t]. Global size (T*V, S*U).
__kernel void depth_views(__global const float *mosaic, __global float *views, const int S, const int T)
{
    const int col = get_global_id(0), row = get_global_id(1);
    if (col >= T * PITCH_V || row >= S * PITCH_U)
        return;
    const int s = row / PITCH_U, u = row - s * PITCH_U, t = col / PITCH_V, v = col - t * PITCH_V;
    views[((size_t)(u * PITCH_V + v) * S + s) * T + t] = mosaic[(size_t)row * T * PITCH_V + col];
}

// 1 for a lens holding any sample that depth_cost leaves out (at or above `saturation`, or not a number): the
// lenses whose taps reach it go to depth_cost, not depth_cost_interior. Global size (T, S).
__kernel void depth_lens_unusable(__global const float *mosaic, __global uchar *flags, const int S, const int T,
                                  const float saturation)
{
    const int t = get_global_id(0), s = get_global_id(1);
    if (t >= T || s >= S)
        return;
    uchar any = 0;
    for (int u = 0; u < PITCH_U; ++u)
        for (int v = 0; v < PITCH_V; ++v)
            any |= !(mosaic[(size_t)(s * PITCH_U + u) * T * PITCH_V + t * PITCH_V + v] < saturation);
    flags[(size_t)s * T + t] = any;
}
