// Fill the dark pixels of every lens (lens weight 0: neither data nor prior once the prior
// is masked, docs/admm.md) with the harmonic extension of the lens's lit pixels:
//
//   x[lens, c, i] = sum_j fill[i * UV + j] * x[lens, c, j]     for each dark pixel i,
//
// fill = -L_dd^-1 L_dl (L the lens's D_uv^T D_uv; zero in lit rows and dark columns), built
// on the host (lfcl/ops/lensfill.py). In place: a dark pixel reads lit pixels only.
// One work-item per lens and colour: global size (T, S, 3).
#define UV (PITCH_U * PITCH_V)

__kernel void lens_fill(__global float *x, __global const float *fill, __global const float *lens_weights,
                        const int height, const int width)
{
    const int t = get_global_id(0), s = get_global_id(1), c = get_global_id(2);
    if (t >= width / PITCH_V || s >= height / PITCH_U) return;
    __global float *lens = x + (size_t)c * height * width + (size_t)(s * PITCH_U) * width + t * PITCH_V;
    for (int i = 0; i < UV; ++i) {
        if (lens_weights[i] > 0.0f) continue;
        __global const float *row = fill + i * UV;
        float acc = 0.0f;
        for (int u = 0; u < PITCH_U; ++u)
            for (int v = 0; v < PITCH_V; ++v)
                acc = fma(row[u * PITCH_V + v], lens[(size_t)u * width + v], acc);
        lens[(size_t)(i / PITCH_V) * width + i % PITCH_V] = acc;
    }
}
