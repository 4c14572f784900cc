// The guarded ADMM start (lfcl/demosaic/guarded_start.py; the float64 references are in lfcl/ops/lensguard.py).
// Planes are [3][height][width], row = s * PITCH_U + u, col = t * PITCH_V + v.
//
// lens_disagreement, one work-item per lens, global size (T, S): how far two starts a and b differ
// over the lens, in noise sigmas at the lens's mean raw level,
//
//   D[s, t] = sqrt( mean_{c, u, v} (a - b)^2 / max(gain * max(level, 0) + floor, FLT_MIN) )
//
// take_lenses, one work-item per pixel, global size (width, height): x = from wherever the pixel's
// lens is marked in chosen[s * T + t], in every plane; x is left as it is elsewhere.

__kernel void lens_disagreement(__global const float *a, __global const float *b, __global const float *mosaic,
                                __global float *out, const int height, const int width,
                                const float gain, const float noise_floor)
{
    const int t = get_global_id(0), s = get_global_id(1);
    const int lenses_t = width / PITCH_V;
    if (t >= lenses_t || s >= height / PITCH_U) return;
    const size_t plane = (size_t)height * width;
    float squared = 0.0f, level = 0.0f;
    for (int u = 0; u < PITCH_U; ++u)
        for (int v = 0; v < PITCH_V; ++v) {
            const size_t i = (size_t)(s * PITCH_U + u) * width + t * PITCH_V + v;
            level += mosaic[i];
            for (int c = 0; c < 3; ++c) {
                const float d = a[c * plane + i] - b[c * plane + i];
                squared = fma(d, d, squared);
            }
        }
    const float samples = (float)(PITCH_U * PITCH_V);
    const float variance = fmax(gain * fmax(level / samples, 0.0f) + noise_floor, FLT_MIN);
    out[(size_t)s * lenses_t + t] = sqrt(squared / (3.0f * samples) / variance);
}

__kernel void take_lenses(__global float *x, __global const float *from, __global const uchar *chosen,
                          const int height, const int width)
{
    const int col = get_global_id(0), row = get_global_id(1);
    if (col >= width || row >= height) return;
    if (!chosen[(size_t)(row / PITCH_U) * (width / PITCH_V) + col / PITCH_V]) return;
    const size_t plane = (size_t)height * width, i = (size_t)row * width + col;
    for (int c = 0; c < 3; ++c)
        x[c * plane + i] = from[c * plane + i];
}

// colour_differences_from, one work-item per pixel, global size (width, height): x keeps its level (the mean of
// its three colours) and moves its colour differences by the share w towards those of m,
// x_c += w (m_c + level - x_c), level = (x_0 + x_1 + x_2 - m_0 - m_1 - m_2) / 3 (w = 1: m's colour differences).
__kernel void colour_differences_from(__global float *x, __global const float *m, const int height, const int width,
                                      const float w)
{
    const int col = get_global_id(0), row = get_global_id(1);
    if (col >= width || row >= height) return;
    const size_t plane = (size_t)height * width, i = (size_t)row * width + col;
    const float level = ((x[i] - m[i]) + (x[plane + i] - m[plane + i]) + (x[2 * plane + i] - m[2 * plane + i])) / 3.0f;
    for (int c = 0; c < 3; ++c) {
        const float xc = x[c * plane + i];
        x[c * plane + i] = fma(w, m[c * plane + i] + level - xc, xc);
    }
}

// guard_lens_means, one work-item per lens, global size (T, S): the safety net's lens-mean guard
// (lfcl/demosaic/safety_net.py). For each colour c, dx = mean_uv x_c - mean_uv m_c is soft-thresholded at
// k sd, sd = sqrt(var(level) / (U V / 4)) (the noise of a mean of a quarter of the lens's samples,
// var = gain * max(level, 0) + floor): x_c += soft(dx, k sd) - dx over the lens, so that x's lens
// mean moves to Malvar's where the two agree within k sd and to within k sd of it elsewhere.
// A lens marked flat whose Malvar mean of some colour lies more than j sd from own[lens][c] (the mean of its
// own samples) is filled with own[lens][c] instead: Malvar's filters read another micro-image there.
// k = inf: no soft threshold (x keeps its lens means; only flat lenses may be filled).
// replaced[s * T + t] = how many colours were moved all the way (|dx| <= k sd), 0..3, or -1 for a filled lens.
__kernel void guard_lens_means(__global float *x, __global const float *m, __global const float *mosaic,
                               __global const uchar *flat, __global const float *own,
                               __global float *replaced, const int height, const int width,
                               const float gain, const float noise_floor, const float k, const float j)
{
    const int t = get_global_id(0), s = get_global_id(1);
    const int lenses_t = width / PITCH_V;
    if (t >= lenses_t || s >= height / PITCH_U) return;
    const size_t plane = (size_t)height * width, lens = (size_t)s * lenses_t + t;
    const float samples = (float)(PITCH_U * PITCH_V);
    float level = 0.0f;
    for (int u = 0; u < PITCH_U; ++u)
        for (int v = 0; v < PITCH_V; ++v)
            level += mosaic[(size_t)(s * PITCH_U + u) * width + t * PITCH_V + v];
    const float variance = fmax(gain * fmax(level / samples, 0.0f) + noise_floor, FLT_MIN);
    const float sd = sqrt(variance / (0.25f * samples)), limit = k * sd;
    float x_mean[3], m_mean[3];
    int fill = 0;
    for (int c = 0; c < 3; ++c) {
        float xs = 0.0f, ms = 0.0f;
        for (int u = 0; u < PITCH_U; ++u)
            for (int v = 0; v < PITCH_V; ++v) {
                const size_t i = c * plane + (size_t)(s * PITCH_U + u) * width + t * PITCH_V + v;
                xs += x[i];
                ms += m[i];
            }
        x_mean[c] = xs / samples;
        m_mean[c] = ms / samples;
        fill |= flat[lens] && fabs(m_mean[c] - own[lens * 3 + c]) > j * sd;
    }
    const int soft = !isinf(k);
    float moved = 0.0f;
    for (int c = 0; c < 3; ++c) {
        const float dx = x_mean[c] - m_mean[c];
        const float kept = copysign(fmax(fabs(dx) - limit, 0.0f), dx);
        moved += soft && fabs(dx) <= limit ? 1.0f : 0.0f;
        const float shift = soft ? kept - dx : 0.0f;
        for (int u = 0; u < PITCH_U; ++u)
            for (int v = 0; v < PITCH_V; ++v) {
                const size_t i = c * plane + (size_t)(s * PITCH_U + u) * width + t * PITCH_V + v;
                x[i] = fill ? own[lens * 3 + c] : x[i] + shift;
            }
    }
    replaced[lens] = fill ? -1.0f : moved;
}
