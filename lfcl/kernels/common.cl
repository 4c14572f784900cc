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
// Programs that use them are built with the lens pitch and the chosen dims as
// constants (-DPITCH_U=9 -DPITCH_V=9 -DDIMS=3): the divisions below compile to
// multiplies and shifts, and the loops over dims unroll to the dims in use.
#define DIM_U 1
#define DIM_V 2
#define DIM_S 4
#define DIM_T 8

// The stencil kernels work on runs of 16 neighbouring samples of one plane row
// (columns col0 .. col0+15, one SIMD register on a CPU): a step along u or s moves
// to another row, a step along v or t stays in the row, and "is there a neighbour"
// is one lane mask per dim.
// Loops over the dims (and directions) carry `#pragma unroll`: with d and dir constant the
// switches in has_neighbour() and neighbour() fold away (D uv ran 46 -> 24 ms at 4500x4500).

// row[col0 + offset + k] for k = 0..15, zero where the column is outside [0, width).
inline float16 load_row(__global const float *row, int col0, int offset, int width)
{
    const int first = col0 + offset;
    if (first >= 0 && first + 16 <= width)
        return vload16(0, row + first);
    float lane[16];
    for (int k = 0; k < 16; ++k)
        lane[k] = first + k >= 0 && first + k < width ? row[first + k] : 0.0f;
    return vload16(0, lane);
}

// row[col0 + k] = v[k] for the lanes inside the row.
inline void store_row(float16 v, __global float *row, int col0, int width)
{
    if (col0 + 16 <= width) {
        vstore16(v, 0, row + col0);
        return;
    }
    float lane[16];
    vstore16(v, 0, lane);
    for (int k = 0; col0 + k < width; ++k)
        row[col0 + k] = lane[k];
}

// Lanes whose sensor pixel measured colour c (the CFA mask, A^T A).
inline int16 measured_lanes(int row, int16 cols, int pattern, int c)
{
    const int16 cell = (int16)((row & 1) << 1) | (cols & 1);
    return (((int16)pattern >> (2 * cell)) & 3) == c;
}

inline int16 lane_columns(int col0)
{
    return col0 + (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
}

#ifdef PITCH_U
// The data-term weights of 16 columns of one row. `weight_runs` tabulates them for every lens
// row u and column phase p = col0 % V (the host's lens weights w[u][v] repeated along the row):
// weight_runs[(u * V + p) * 16 + k] = w[u][(p + k) % V], one aligned load per run instead of a
// 16-lane gather (lfcl/solvers/admm.py weight_runs_np). w[u][v] itself is entry (u * V + v) * 16.
inline float16 row_weights(__global const float *weight_runs, int row, int16 cols)
{
    return vload16((row % PITCH_U) * PITCH_V + cols.s0 % PITCH_V, weight_runs);
}

// Lanes (all ones) that have a neighbour one step along dim d in direction dir (+1: next,
// -1: previous): the Neumann boundary. Rows split as s*U + u, columns as t*V + v.
inline int16 has_neighbour(int d, int dir, int row, int16 cols, int height, int width)
{
    switch (d) {
    case DIM_U: return (int16)(-(dir > 0 ? row % PITCH_U < PITCH_U - 1 : row % PITCH_U > 0));
    case DIM_V: return dir > 0 ? cols % PITCH_V < PITCH_V - 1 : cols % PITCH_V > 0;
    case DIM_S: return (int16)(-(dir > 0 ? row / PITCH_U < height / PITCH_U - 1 : row >= PITCH_U));
    default:    return dir > 0 ? cols < width - PITCH_V : cols >= PITCH_V;
    }
}

// The 16 samples one step along dim d (direction dir) from row, col0 .. col0+15 of
// `plane`; zero off the plane (has_neighbour masks the rest).
inline float16 neighbour(__global const float *plane, int d, int dir, int row, int col0, int height, int width)
{
    int r = row, offset = 0;
    switch (d) {
    case DIM_U: r += dir; break;
    case DIM_S: r += dir * PITCH_U; break;
    case DIM_V: offset = dir; break;
    default:    offset = dir * PITCH_V; break;
    }
    if (r < 0 || r >= height) return (float16)0.0f;
    return load_row(plane + (size_t)r * width, col0, offset, width);
}
// With dark pixels left out of the prior (docs/admm.md): lanes linked to their neighbour one
// step along dim d (direction dir), i.e. the neighbour exists and both samples have a lens
// weight > 0. Whether the two lens pixels are both lit repeats from lens to lens, so the host
// tabulates it for every run of 16 columns: `links` holds, for each (dim, direction) pair
// 2 * (0: u, 1: v, 2: s, 3: t) + (dir > 0), lens row u and column phase col0 % V, 16 floats
// (1: both lit), in that order (lfcl/ops/gradient.py link_table): one aligned load a run.
inline int16 linked(__global const float *links, int d, int dir, int row, int16 cols, int height, int width)
{
    const int pair = 2 * (d == DIM_U ? 0 : d == DIM_V ? 1 : d == DIM_S ? 2 : 3) + (dir > 0);
    const float16 lit = vload16((pair * PITCH_U + row % PITCH_U) * PITCH_V + cols.s0 % PITCH_V, links);
    return has_neighbour(d, dir, row, cols, height, width) & (lit != 0.0f);
}

// PRIOR_MASK (build-time, 0 or 1): whether the prior's differences are masked by the lens
// weights. LINK is then linked() with the kernel's `links` argument, else has_neighbour().
#ifndef PRIOR_MASK
#define PRIOR_MASK 0
#endif
#if PRIOR_MASK
#define LINK(d, dir, row, cols, height, width) linked(links, d, dir, row, cols, height, width)
#else
#define LINK(d, dir, row, cols, height, width) has_neighbour(d, dir, row, cols, height, width)
#endif

// D^T M D x without the intermediate gradient: a 4D Laplacian with Neumann ends over the kept
// differences (M: all of them without PRIOR_MASK, the linked ones with it),
//   (D^T M D x)[i] = sum_d [next kept] (x[i] - x[next]) + [previous kept] (x[i] - x[previous]).
inline float16 laplacian(__global const float *links, __global const float *plane, float16 xi,
                         int row, int col0, int height, int width)
{
    const int16 cols = lane_columns(col0);
    float16 acc = (float16)0.0f;
    #pragma unroll
    for (int d = 1; d <= DIM_T; d <<= 1) {
        if (!(DIMS & d)) continue;
        #pragma unroll
        for (int dir = -1; dir <= 1; dir += 2) {
            const float16 other = neighbour(plane, d, dir, row, col0, height, width);
            acc += select((float16)0.0f, xi - other, LINK(d, dir, row, cols, height, width));
        }
    }
    return acc;
}
#define LAPLACIAN(plane, xi, row, col0, height, width) laplacian(links, plane, xi, row, col0, height, width)
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
