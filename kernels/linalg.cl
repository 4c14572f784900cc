// Vector updates for the conjugate-gradient solver, on flat float arrays of n
// elements:
//
//   axpby:  out = a x + b y      (out may be x or y: each element is read before it is written)
//
// Work-item k handles chunk k, the 16 floats [16k, 16k + 16) (one SIMD register
// on a CPU); the last chunk may be short. Global size: ceil(n / 16), rounded up.

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

__kernel void axpby(const float a, __global const float *x, const float b, __global const float *y,
                    __global float *out, const ulong n)
{
    const ulong k = get_global_id(0);
    if (k * LANES >= n) return;
    store_chunk(a * load_chunk(x, k, n) + b * load_chunk(y, k, n), out, k, n);
}
