// Copy whole lenses between two lens grids (lfcl/ops/lenscopy.py, the freezing of converged
// lenses in lfcl/solvers/freeze.py). Arrays are stacks of planes shaped like the sensor,
// plane[p][row][col], row = s * PITCH_U + u, col = t * PITCH_V + v, with src_lenses resp.
// dst_lenses lenses per lens row. Pair k = (pairs[2k], pairs[2k + 1]) copies source lens
// index s * src_lenses + t to destination lens index s' * dst_lenses + t', in every plane;
// a source index of -1 writes zeros (the padding lenses of a smaller grid).
// Global size (pair count, planes); one work-item copies one lens of one plane.
__kernel void copy_lenses(__global const float *src, const int src_lenses, const int src_lens_rows,
                          __global float *dst, const int dst_lenses, const int dst_lens_rows,
                          __global const int *pairs, const int count)
{
    const int k = get_global_id(0), p = get_global_id(1);
    if (k >= count) return;
    const int from = pairs[2 * k], to = pairs[2 * k + 1];
    const size_t src_width = (size_t)src_lenses * PITCH_V, dst_width = (size_t)dst_lenses * PITCH_V;
    __global float *out = dst + (size_t)p * dst_lens_rows * PITCH_U * dst_width
                        + (size_t)(to / dst_lenses) * PITCH_U * dst_width + (size_t)(to % dst_lenses) * PITCH_V;
    if (from < 0) {
        for (int u = 0; u < PITCH_U; ++u)
            for (int v = 0; v < PITCH_V; ++v)
                out[(size_t)u * dst_width + v] = 0.0f;
        return;
    }
    __global const float *in = src + (size_t)p * src_lens_rows * PITCH_U * src_width
                             + (size_t)(from / src_lenses) * PITCH_U * src_width + (size_t)(from % src_lenses) * PITCH_V;
    for (int u = 0; u < PITCH_U; ++u)
        for (int v = 0; v < PITCH_V; ++v)
            out[(size_t)u * dst_width + v] = in[(size_t)u * src_width + v];
}

// Set whole lenses to constants: lens lenses[k] (index s * T + t of a grid of `lens_count` lenses
// per lens row) of plane p becomes values[k * planes + p] at every pixel (the flat lenses' colour
// means, lfcl/demosaic/flat_lenses.py). Global size (count, planes); one work-item fills one lens of one plane.
__kernel void fill_lenses(__global float *dst, const int lens_count, const int lens_rows,
                          __global const int *lenses, __global const float *values, const int count)
{
    const int k = get_global_id(0), p = get_global_id(1), planes = get_global_size(1);
    if (k >= count) return;
    const int lens = lenses[k];
    const size_t width = (size_t)lens_count * PITCH_V;
    __global float *out = dst + (size_t)p * lens_rows * PITCH_U * width
                        + (size_t)(lens / lens_count) * PITCH_U * width + (size_t)(lens % lens_count) * PITCH_V;
    const float value = values[(size_t)k * planes + p];
    for (int u = 0; u < PITCH_U; ++u)
        for (int v = 0; v < PITCH_V; ++v)
            out[(size_t)u * width + v] = value;
}
