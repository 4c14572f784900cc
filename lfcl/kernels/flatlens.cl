// Per-lens colour means and the chi-square of "this lens is flat" (lfcl/ops/flatlens.py has the
// maths and the float64 reference lens_flatness_np). For lens (s, t) and colour c, over its lit
// pixels P_c (lens weight w > 0):
//
//   mu_c = sum_{P_c} w x / sum_{P_c} w
//   chi2 = sum_c sum_{P_c} (x - mu_c)^2 / max(var, VARIANCE_FLOOR),   var = (gain sqrt(w) mu_c+ + floor) / w
//
// out[s, t] = (mu_R, mu_G, mu_B, chi2); a colour without a lit pixel gets mean 0 and adds nothing.
// One work-item per lens: global size (T, S). Built with PITCH_U, PITCH_V (grid_defines).

#define VARIANCE_FLOOR 1e-12f  // = flatlens.VARIANCE_FLOOR: no read noise, zero mean

__kernel void lens_flatness(__global const float *mosaic, __global const float *lens_weights,
                            __global float *out, const int height, const int width, const int pattern,
                            const float gain, const float noise_floor)
{
    const int t = get_global_id(0), s = get_global_id(1);
    const int lenses_t = width / PITCH_V;
    if (t >= lenses_t || s >= height / PITCH_U) return;
    const int row0 = s * PITCH_U, col0 = t * PITCH_V;
    __global const float *lens = mosaic + (size_t)row0 * width + col0;

    // Pass 1: weighted sums per colour, taken relative to the colour's first lit sample: the
    // float sums then hold only the spread around it, and the mean comes as ref + offset with
    // the offset exact to float even when the level is far above the noise.
    float ref[3] = {0.0f, 0.0f, 0.0f}, sum_w[3] = {0.0f, 0.0f, 0.0f}, sum_wd[3] = {0.0f, 0.0f, 0.0f};
    for (int u = 0; u < PITCH_U; ++u)
        for (int v = 0; v < PITCH_V; ++v) {
            const float w = lens_weights[u * PITCH_V + v];
            if (!(w > 0.0f)) continue;
            const int c = bayer_colour(row0 + u, col0 + v, pattern);
            const float x = lens[(size_t)u * width + v];
            if (sum_w[c] == 0.0f) ref[c] = x;
            sum_w[c] += w;
            sum_wd[c] = fma(w, x - ref[c], sum_wd[c]);
        }
    float offset[3], mean[3];
    for (int c = 0; c < 3; ++c) {
        offset[c] = sum_w[c] > 0.0f ? sum_wd[c] / sum_w[c] : 0.0f;
        mean[c] = ref[c] + offset[c];  // 0 for a colour without a lit pixel
    }

    // Pass 2: squared residuals around the means (not sum x^2 - n mu^2, which cancels), each over
    // its variance under the Poisson-Gaussian model carried through the flat field. The residual
    // is (x - ref) - offset: x - mean would carry the rounding of mean to float (half an ulp of
    // the level), a bias that matters once the noise is a few thousand ulps or less.
    float chi2 = 0.0f;
    for (int u = 0; u < PITCH_U; ++u)
        for (int v = 0; v < PITCH_V; ++v) {
            const float w = lens_weights[u * PITCH_V + v];
            if (!(w > 0.0f)) continue;
            const int c = bayer_colour(row0 + u, col0 + v, pattern);
            const float r = (lens[(size_t)u * width + v] - ref[c]) - offset[c];
            const float var = (gain * sqrt(w) * fmax(mean[c], 0.0f) + noise_floor) / w;
            chi2 += r * r / fmax(var, VARIANCE_FLOOR);
        }

    __global float *o = out + 4 * ((size_t)s * lenses_t + t);
    o[0] = mean[0];
    o[1] = mean[1];
    o[2] = mean[2];
    o[3] = chi2;
}
