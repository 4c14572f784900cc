// Malvar-He-Cutler (2004) linear demosaicing of a Bayer mosaic.
//
// H. S. Malvar, L. He, R. Cutler, "High-quality linear interpolation for
// demosaicing of Bayer-patterned color images", ICASSP 2004. Every missing colour
// is a 5x5 linear filter of the mosaic (coefficients / 8): a bilinear estimate
// corrected by the Laplacian of the colour measured at the pixel. The pixel's own
// colour is copied unchanged. Output is not clipped.
//
// Border: the mosaic is extended by mirror reflection about the edge sample,
// without repeating it (index -1 -> 1, -2 -> 2, n -> n-2, n+1 -> n-3; numpy's
// pad mode 'reflect', scipy.ndimage's mode 'mirror'). The extension is periodic
// with period 2(n-1), so for n == 2 the fold repeats (-2 -> 0, 3 -> 1) and, for
// any n >= 2, every extended sample keeps its true CFA colour (period is even).
// For n == 1 every index maps to 0. All indices land in [0, n).
//
// Lens-bounded (lens_u, lens_v > 0): the same mirror, about each lens's edge samples
// instead of the sensor's, so that no filter reads a neighbouring micro-image (a lens of
// lens_u x lens_v pixels is treated as an image of its own; H and W are whole lenses).
// lens_u = lens_v = 0: the whole sensor is one image (the paper's Malvar).
//
// Input: mosaic [H, W] float32. Output: planes [3, H, W] float32 (R, G, B), or, built with
// -DINTERLEAVED=1, an image [H, W, 3] (the public lfcl.malvar's layout: no transpose on the host).
// Global size: (W, H), or a band of rows through the global offset; work-items past the image return.

#ifndef INTERLEAVED
#define INTERLEAVED 0
#endif

// Mirror index i into [0, n): fold with period 2(n-1) (numpy pad 'reflect').
inline int mirror_index(int i, int n)
{
    if (n <= 1) return 0;
    const int period = 2 * (n - 1);
    int m = i % period;
    if (m < 0) m += period;
    return m < n ? m : period - m;
}

// mirror_index for i in [-2, n + 1] and n >= 3, without the division (the lens-bounded
// path takes it for most pixels of a small lens).
inline int mirror_near(int i, int n)
{
    if (n < 3) return mirror_index(i, n);
    return i < 0 ? -i : (i >= n ? 2 * (n - 1) - i : i);
}

// The 13 samples of the 5x5 support that the filters use, named by offset:
// C centre; N1/S1/W1/E1 one step up/down/left/right; N2/S2/W2/E2 two steps;
// D the sum of the four diagonal neighbours (+-1, +-1).
typedef struct {
    float C;
    float N1, S1, W1, E1;
    float N2, S2, W2, E2;
    float D;
} neighbourhood;

// G at an R or B pixel (paper Fig. 2, "G at R locations" / "G at B locations"):
//   [ 0  0 -1  0  0 ]
//   [ 0  0  2  0  0 ]
//   [-1  2  4  2 -1 ] / 8
//   [ 0  0  2  0  0 ]
//   [ 0  0 -1  0  0 ]
inline float g_at_rb(const neighbourhood p)
{
    return (4.0f * p.C
            + 2.0f * (p.N1 + p.S1 + p.W1 + p.E1)
            - (p.N2 + p.S2 + p.W2 + p.E2)) * 0.125f;
}

// R at G in an R row / B column, and B at G in a B row / R column: the colour
// sought sits left and right of the pixel (paper Fig. 2, "R at green in R row,
// B column"):
//   [ 0   0  1/2  0   0 ]
//   [ 0  -1   0  -1   0 ]
//   [-1   4   5   4  -1 ] / 8
//   [ 0  -1   0  -1   0 ]
//   [ 0   0  1/2  0   0 ]
inline float rb_at_g_horizontal(const neighbourhood p)
{
    return (5.0f * p.C
            + 4.0f * (p.W1 + p.E1)
            - (p.W2 + p.E2)
            - p.D
            + 0.5f * (p.N2 + p.S2)) * 0.125f;
}

// R at G in a B row / R column, and B at G in an R row / B column: the colour
// sought sits above and below the pixel (the transpose of the filter above).
inline float rb_at_g_vertical(const neighbourhood p)
{
    return (5.0f * p.C
            + 4.0f * (p.N1 + p.S1)
            - (p.N2 + p.S2)
            - p.D
            + 0.5f * (p.W2 + p.E2)) * 0.125f;
}

// R at B and B at R (paper Fig. 2, "R at blue in B row, B column"):
//   [ 0    0  -3/2  0    0  ]
//   [ 0    2    0   2    0  ]
//   [-3/2  0    6   0  -3/2 ] / 8
//   [ 0    2    0   2    0  ]
//   [ 0    0  -3/2  0    0  ]
inline float rb_at_br(const neighbourhood p)
{
    return (6.0f * p.C
            + 2.0f * p.D
            - 1.5f * (p.N2 + p.S2 + p.W2 + p.E2)) * 0.125f;
}

__kernel void malvar(__global const float *mosaic, __global float *planes,
                     const int height, const int width, const int pattern,
                     const int lens_u, const int lens_v)
{
    const int col = get_global_id(0), row = get_global_id(1);
    if (col >= width || row >= height) return;

    // The image the filters see: the sensor, or the pixel's lens (u, v: the pixel in it).
    const int span_u = lens_u > 0 ? lens_u : height, span_v = lens_v > 0 ? lens_v : width;
    const int u = lens_u > 0 ? row % lens_u : row, v = lens_v > 0 ? col % lens_v : col;
    // Row / column indices for offsets -2 .. +2 (index 2 is the centre); only the
    // 2-pixel frame needs the mirror (integer divisions are slow on a CPU).
    int r[5], c[5];
    if (u >= 2 && u + 2 < span_u && v >= 2 && v + 2 < span_v) {
        for (int k = 0; k < 5; ++k) {
            r[k] = (row + k - 2) * width;
            c[k] = col + k - 2;
        }
    } else {
        for (int k = 0; k < 5; ++k) {
            r[k] = (row - u + mirror_near(u + k - 2, span_u)) * width;
            c[k] = col - v + mirror_near(v + k - 2, span_v);
        }
    }
#define AT(dr, dc) mosaic[r[2 + (dr)] + c[2 + (dc)]]
    neighbourhood p;
    p.C  = AT(0, 0);
    p.N1 = AT(-1, 0); p.S1 = AT(1, 0); p.W1 = AT(0, -1); p.E1 = AT(0, 1);
    p.N2 = AT(-2, 0); p.S2 = AT(2, 0); p.W2 = AT(0, -2); p.E2 = AT(0, 2);
    p.D  = AT(-1, -1) + AT(-1, 1) + AT(1, -1) + AT(1, 1);
#undef AT

    // Colours follow sensor parity (bayer_colour), never the mirrored neighbours.
    const int own = bayer_colour(row, col, pattern);
    float red, green, blue;
    if (own == 1) {
        green = p.C;
        const float horizontal = rb_at_g_horizontal(p), vertical = rb_at_g_vertical(p);
        if (bayer_colour(row, col + 1, pattern) == 0) {  // R row, B column
            red = horizontal;
            blue = vertical;
        } else {                                          // B row, R column
            red = vertical;
            blue = horizontal;
        }
    } else {
        green = g_at_rb(p);
        const float other = rb_at_br(p);
        red = own == 0 ? p.C : other;
        blue = own == 2 ? p.C : other;
    }

    const size_t i = (size_t)row * width + col;
#if INTERLEAVED
    planes[3 * i] = red;
    planes[3 * i + 1] = green;
    planes[3 * i + 2] = blue;
#else
    const size_t plane = (size_t)height * width;
    planes[i] = red;
    planes[plane + i] = green;
    planes[2 * plane + i] = blue;
#endif
}
