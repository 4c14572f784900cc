// Shared helpers, prefixed to every lfcl program.
//
// Layout (docs/layout.md): a light field lives in three colour planes shaped like
// the sensor, plane[c][row][col] with row = s*U + u, col = t*V + v.

// Colour (0=R, 1=G, 2=B) of sensor pixel (row, col). `pattern` packs the 2x2 Bayer
// cell, 2 bits per entry, entry index 2*(row&1) + (col&1); the host folds the
// crop origin's parity into it, so the colour always follows sensor coordinates.
inline int bayer_colour(int row, int col, int pattern)
{
    return (pattern >> (2 * (((row & 1) << 1) | (col & 1)))) & 3;
}

// Steps of the 4D grid on the sensor-shaped planes (row = s*U + u, col = t*V + v,
// W = T*V): u: W, v: 1, s: U*W, t: V. Dims are bits of a mask (u=1, v=2, s=4, t=8).
// Programs that use them are built with the lens pitch as constants (-DPITCH_U=9
// -DPITCH_V=9), so the divisions below compile to multiplies and shifts.
#define DIM_U 1
#define DIM_V 2
#define DIM_S 4
#define DIM_T 8

#ifdef PITCH_U
// Is there a next sample along dim d from (row, col)?
inline int has_next(int d, int row, int col, int height, int width)
{
    switch (d) {
    case DIM_U: return (row % PITCH_U) < PITCH_U - 1;
    case DIM_V: return (col % PITCH_V) < PITCH_V - 1;
    case DIM_S: return row / PITCH_U < height / PITCH_U - 1;
    default:    return col / PITCH_V < width / PITCH_V - 1;
    }
}

inline int has_prev(int d, int row, int col)
{
    switch (d) {
    case DIM_U: return (row % PITCH_U) > 0;
    case DIM_V: return (col % PITCH_V) > 0;
    case DIM_S: return row >= PITCH_U;
    default:    return col >= PITCH_V;
    }
}

inline size_t step_of(int d, int width)
{
    switch (d) {
    case DIM_U: return (size_t)width;
    case DIM_V: return 1;
    case DIM_S: return (size_t)PITCH_U * width;
    default:    return (size_t)PITCH_V;
    }
}
#endif

// Flat arrays are processed in chunks of 16 floats (one SIMD register on a CPU);
// only the last chunk of n floats may be short.
#define LANES 16

// Chunk k of x, zero-padded past the end n.
inline float16 load_chunk(__global const float *x, ulong k, ulong n)
{
    if ((k + 1) * LANES <= n)
        return vload16(k, x);
    float lane[LANES];
    for (ulong i = 0; i < LANES; ++i)
        lane[i] = k * LANES + i < n ? x[k * LANES + i] : 0.0f;
    return vload16(0, lane);
}

// Chunk k of x = v, dropping the lanes past the end n.
inline void store_chunk(float16 v, __global float *x, ulong k, ulong n)
{
    if ((k + 1) * LANES <= n) {
        vstore16(v, k, x);
        return;
    }
    float lane[LANES];
    vstore16(v, 0, lane);
    for (ulong i = 0; i < LANES && k * LANES + i < n; ++i)
        x[k * LANES + i] = lane[i];
}
