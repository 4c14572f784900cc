// Window aggregation of a stack of lens maps (step 2 of lfcl/depth/estimate.py; twin:
// lfcl.depth.cost.aggregate_window_np):
//   out[p][s][t] = sum over (dy, dx) in [-R, R]^2 of weights[o][s][t] * maps[p][s + dy][t + dx],
// o = (dy + R) (2R + 1) + (dx + R); lenses outside the frame count as 0. The weights belong to the
// window's centre lens (its guide), so one work-item per (t, s, p) reads its own 81 weights.
// Global size (T, S, P).
__kernel void depth_aggregate(__global const float *maps, __global const float *weights, __global float *out,
                              const int S, const int T, const int P, const int radius)
{
    const int t = get_global_id(0), s = get_global_id(1), p = get_global_id(2);
    if (t >= T || s >= S || p >= P)
        return;
    const size_t lenses = (size_t)S * T;
    __global const float *map = maps + (size_t)p * lenses;
    const int side = 2 * radius + 1;
    float acc = 0.0f;
    for (int dy = -radius; dy <= radius; ++dy) {
        const int ss = s + dy;
        if (ss < 0 || ss >= S)
            continue;
        for (int dx = -radius; dx <= radius; ++dx) {
            const int tt = t + dx;
            if (tt < 0 || tt >= T)
                continue;
            const int o = (dy + radius) * side + dx + radius;
            acc += weights[(size_t)o * lenses + (size_t)s * T + t] * map[(size_t)ss * T + tt];
        }
    }
    out[(size_t)p * lenses + (size_t)s * T + t] = acc;
}
