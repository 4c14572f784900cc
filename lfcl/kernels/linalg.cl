// Vector updates for the conjugate-gradient solver, on flat float arrays of n
// elements:
//
//   axpby:  out = a x + b y      (out may be x or y: each element is read before it is written)
//
// Work-item k handles chunk k, the 16 floats [16k, 16k + 16) (one SIMD register
// on a CPU); the last chunk may be short. Global size: ceil(n / 16), rounded up.

__kernel void axpby(const float a, __global const float *x, const float b, __global const float *y,
                    __global float *out, const ulong n)
{
    const ulong k = get_global_id(0);
    if (k * LANES >= n) return;
    store_chunk(a * load_chunk(x, k, n) + b * load_chunk(y, k, n), out, k, n);
}
