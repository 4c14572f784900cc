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
