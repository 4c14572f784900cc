// Window aggregation of a stack of lens maps (step 2 of lfcl/depth/estimate.py; twin:
// lfcl.depth.cost.aggregate_window_np):
//   out[p][s][t] = sum over (dy, dx) in [-R, R]^2 of weights[o][s][t] * maps[p][s + dy][t + dx],
// o = (dy + R) (2R + 1) + (dx + R); lenses outside the frame count as 0. The weights belong to the
// window's centre lens (its guide). The maps are planes first .. first + P - 1 of a larger stack (one
// aperture of a cost volume).
// One work-item per (t, s) and CHUNK (build-time constant) consecutive planes: each weight is read once for CHUNK planes
// (one work-item per plane read it once per plane, 2x the loads; docs/depth.md, "Timing").
// Global size (T, S, ceil(P / CHUNK)).
__kernel void depth_aggregate(__global const float *maps, __global const float *weights, __global float *out,
                              const int S, const int T, const int P, const int radius, const int first)
{
    const int t = get_global_id(0), s = get_global_id(1), p0 = get_global_id(2) * CHUNK;
    if (t >= T || s >= S || p0 >= P)
        return;
    const size_t lenses = (size_t)S * T;
    const int n = min(CHUNK, P - p0);
    __global const float *map = maps + (size_t)(first + p0) * lenses;
    const int side = 2 * radius + 1;
    float acc[CHUNK];
    for (int j = 0; j < CHUNK; ++j)
        acc[j] = 0.0f;
    for (int dy = -radius; dy <= radius; ++dy) {
        const int ss = s + dy;
        if (ss < 0 || ss >= S)
            continue;
        for (int dx = -radius; dx <= radius; ++dx) {
            const int tt = t + dx;
            if (tt < 0 || tt >= T)
                continue;
            const int o = (dy + radius) * side + dx + radius;
            const float w = weights[(size_t)o * lenses + (size_t)s * T + t];
            const size_t at = (size_t)ss * T + tt;
            for (int j = 0; j < n; ++j)
                acc[j] += w * map[(size_t)j * lenses + at];
        }
    }
    for (int j = 0; j < n; ++j)
        out[(size_t)(p0 + j) * lenses + (size_t)s * T + t] = acc[j];
}
