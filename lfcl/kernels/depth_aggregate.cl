// Window aggregation of a stack of lens maps (step 2 of lfcl/depth/estimate.py; twin:
// lfcl.depth.cost.aggregate_window_np):
//   out[p][s][t] = sum over (dy, dx) in [-R, R]^2 of weights[o][s][t] * maps[p][s + dy][t + dx],
// o = (dy + R) (2R + 1) + (dx + R); lenses outside the frame count as 0. The weights belong to the
// window's centre lens (its guide). The maps are planes first .. first + P - 1 of a larger stack (one
// aperture of a cost volume).
// One work-item per AGG_LANES (8) lenses along a row and CHUNK (build-time constant) consecutive planes: each
// weight is read once for CHUNK planes (one work-item per plane read it once per plane, 2x the loads;
// docs/depth.md, "Timing"), and the 8 lenses are one vector load each (the kernels run scalar per work-item on
// a CPU; the vector type is what fills its SIMD lanes). A window row that runs past the frame's side, or a
// work-item holding the row's last lenses, takes its lanes one by one.
// Global size (ceil(T / AGG_LANES), S, ceil(P / CHUNK)).
#define AGG_LANES 8

inline float8 lanes_at(__global const float *row, const int t, const int T)
{
    float lane[AGG_LANES];
    for (int j = 0; j < AGG_LANES; ++j)
        lane[j] = t + j >= 0 && t + j < T ? row[t + j] : 0.0f;
    return vload8(0, lane);
}

__kernel void depth_aggregate(__global const float *maps, __global const float *weights, __global float *out,
                              const int S, const int T, const int P, const int radius, const int first)
{
    const int t0 = get_global_id(0) * AGG_LANES, s = get_global_id(1), p0 = get_global_id(2) * CHUNK;
    if (t0 >= T || s >= S || p0 >= P)
        return;
    const size_t lenses = (size_t)S * T;
    const int n = min(CHUNK, P - p0);
    const bool whole = t0 + AGG_LANES <= T;
    __global const float *map = maps + (size_t)(first + p0) * lenses;
    const int side = 2 * radius + 1;
    float8 acc[CHUNK];
    for (int j = 0; j < CHUNK; ++j)
        acc[j] = (float8)(0.0f);
    for (int dy = -radius; dy <= radius; ++dy) {
        const int ss = s + dy;
        if (ss < 0 || ss >= S)
            continue;
        for (int dx = -radius; dx <= radius; ++dx) {
            const int o = (dy + radius) * side + dx + radius;
            __global const float *weight_row = weights + (size_t)o * lenses + (size_t)s * T;
            const float8 w = whole ? vload8(0, weight_row + t0) : lanes_at(weight_row, t0, T);
            const int tt = t0 + dx;
            if (whole && tt >= 0 && tt + AGG_LANES <= T) {
                for (int j = 0; j < n; ++j)
                    acc[j] += w * vload8(0, map + (size_t)j * lenses + (size_t)ss * T + tt);
            } else {
                for (int j = 0; j < n; ++j)
                    acc[j] += w * lanes_at(map + (size_t)j * lenses + (size_t)ss * T, tt, T);
            }
        }
    }
    for (int j = 0; j < n; ++j) {
        __global float *row = out + (size_t)(p0 + j) * lenses + (size_t)s * T;
        if (whole) {
            vstore8(acc[j], 0, row + t0);
        } else {
            float lane[AGG_LANES];
            vstore8(acc[j], 0, lane);
            for (int l = 0; l < AGG_LANES && t0 + l < T; ++l)
                row[t0 + l] = lane[l];
        }
    }
}

// Step 3's choice between apertures, one aperture at a time (twin: lfcl/depth/estimate.py take_aperture_np): from
// an aperture's window sums (`sums`: [2 ND, S, T], excess then weight), per lens its cost curve excess / weight, the
// cost's noise sigma = sqrt(2 / (largest weight)) and its score, the curve's minimum (plus 2 sigma for a half
// aperture, which must beat the full one by twice its own noise); where the score is lower than the best so far
// (or `first`), the lens takes this aperture's curve, score and noise. Global size (T, S).
__kernel void depth_take_aperture(__global const float *sums, __global float *curve, __global float *score,
                                  __global float *noise, const int S, const int T, const int ND,
                                  const int half_aperture, const int first)
{
    const int t = get_global_id(0), s = get_global_id(1);
    if (t >= T || s >= S)
        return;
    const size_t lenses = (size_t)S * T, at = (size_t)s * T + t;
    float largest = 0.0f, lowest = INFINITY;
    for (int k = 0; k < ND; ++k) {
        const float weight = sums[(size_t)(ND + k) * lenses + at];
        largest = fmax(largest, weight);
        lowest = fmin(lowest, sums[(size_t)k * lenses + at] / fmax(weight, 1e-12f));
    }
    const float sigma = sqrt(2.0f / fmax(largest, 1e-12f));
    const float mine = lowest + (half_aperture ? 2.0f * sigma : 0.0f);
    if (first || mine < score[at]) {
        score[at] = mine;
        noise[at] = sigma;
        for (int k = 0; k < ND; ++k)
            curve[(size_t)k * lenses + at] =
                sums[(size_t)k * lenses + at] / fmax(sums[(size_t)(ND + k) * lenses + at], 1e-12f);
    }
}

// The window weights (twin: lfcl/depth/estimate.py _window_weights): for window offset o = (dy, dx) of lens (s, t),
// exp(-sum over colours of (guide[c][s + dy][t + dx] - guide[c][s][t])^2 scale[c][s][t]), 0 for a neighbour outside
// the frame; `scale` = 1 / (3 nv sigma^2) per colour and lens. weights [(2R + 1)^2, S, T].
// Global size (T, S, (2R + 1)^2).
__kernel void depth_window_weights(__global const float *guide, __global const float *scale, __global float *weights,
                                   const int S, const int T, const int radius)
{
    const int t = get_global_id(0), s = get_global_id(1), o = get_global_id(2);
    const int side = 2 * radius + 1;
    if (t >= T || s >= S || o >= side * side)
        return;
    const int ss = s + o / side - radius, tt = t + o % side - radius;
    const size_t lenses = (size_t)S * T, at = (size_t)s * T + t;
    float weight = 0.0f;
    if (ss >= 0 && ss < S && tt >= 0 && tt < T) {
        float z = 0.0f;
        for (int c = 0; c < 3; ++c) {
            const float diff = guide[c * lenses + (size_t)ss * T + tt] - guide[c * lenses + at];
            z += diff * diff * scale[c * lenses + at];
        }
        weight = exp(-z);
    }
    weights[(size_t)o * lenses + at] = weight;
}
