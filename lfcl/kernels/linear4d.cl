// Learned 4D linear demosaic (lfcl/ops/linear4d.py, docs/linear4d.md).
//
// Every colour of every pixel is a linear combination of mosaic taps at 4D offsets
// (ds, dt, du, dv): planes[c][row][col] = sum_k w[row mod 2U][c][k][col mod 2V] *
// mosaic[tap k]. The coefficients depend on the pixel's (u, v) and its CFA class,
// i.e. on row mod 2U and col mod 2V with an odd pitch; the host expands them into
// `tables` [2U][3][n_taps][2V + 16] so that 16 neighbouring columns are one load.
//
// Borders. A tap outside the pixel's lens (u + du or v + dv off the lens) has
// coefficient 0 in the tables, so whatever in-image pixel it reads does not count.
// A cross-lens tap whose lens lies outside the image reads the lens on the other
// side (offsets .y / .w below: s - ds instead of s + ds, an even number of rows or
// columns away, so the CFA colour is kept); if that is outside too, it reads 0.
// For a tap that stays inside its lens, "lens outside the image" is exactly "row
// (column) outside the image".
//
// Input: mosaic [H, W] float32; tables as above; offsets[k] = (row offset du + ds*U,
// mirrored du - ds*U, column offset dv + dt*V, mirrored dv - dt*V). Output: planes
// [3, H, W] float32. Built with -DLENS_U, -DLENS_V. Global size (ceil(W / 16), H):
// one work-item per 16 neighbouring pixels of a row (one SIMD register on a CPU).

#define PHASE_ROWS (2 * LENS_U)
#define PHASE_COLS (2 * LENS_V)
#define TABLE_COLS (PHASE_COLS + 16)

__kernel void linear4d(__global const float *mosaic, __global float *planes,
                       __global const float *tables, __global const int4 *offsets,
                       const int n_taps, const int height, const int width)
{
    const int col0 = get_global_id(0) * 16, row = get_global_id(1);
    if (col0 >= width || row >= height) return;

    const size_t tap_stride = TABLE_COLS;
    const size_t colour_stride = (size_t)n_taps * TABLE_COLS;
    __global const float *table = tables + (size_t)(row % PHASE_ROWS) * 3 * colour_stride + col0 % PHASE_COLS;
    const int16 cols = lane_columns(col0);

    float16 red = (float16)0.0f, green = (float16)0.0f, blue = (float16)0.0f;
    for (int k = 0; k < n_taps; ++k) {
        const int4 o = offsets[k];
        int r = row + o.x;
        if (r < 0 || r >= height) r = row + o.y;   // the lens row on the other side
        if (r < 0 || r >= height) continue;        // none: the tap reads 0
        __global const float *src = mosaic + (size_t)r * width;

        float16 x;
        if (col0 + o.z >= 0 && col0 + 15 + o.z < width) {
            x = vload16(0, src + col0 + o.z);
        } else {
            // Lanes whose tap column is off the image take the lens column on the other side.
            const int16 c = cols + o.z;
            x = select(load_row(src, col0, o.w, width), load_row(src, col0, o.z, width), (c >= 0) & (c < width));
        }
        __global const float *w = table + k * tap_stride;
        red = fma(vload16(0, w), x, red);
        green = fma(vload16(0, w + colour_stride), x, green);
        blue = fma(vload16(0, w + 2 * colour_stride), x, blue);
    }

    const size_t plane = (size_t)height * width;
    __global float *out = planes + (size_t)row * width;
    store_row(red, out, col0, width);
    store_row(green, out + plane, col0, width);
    store_row(blue, out + 2 * plane, col0, width);
}
