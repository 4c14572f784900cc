// Shrinkage for the scaled-form ADMM (paper, section 3.4), element-wise on n floats:
//
//   soft threshold:  S_kappa(v) = sign(v) max(|v| - kappa, 0)       (kappa = lambda / rho >= 0)
//   z/u update:      v = D x + u,  z' = S_kappa(v),  u' = v - z',  dz = z' - z
//
// dz feeds the dual residual rho D^T (z' - z). A NaN in v stays NaN in z'.
// Work-item k handles chunk k, the 16 floats [16k, 16k + 16) (one SIMD register
// on a CPU); the last chunk may be short. Global size: ceil(n / 16), rounded up.

// S_kappa(v) = sign(v) max(|v| - kappa, 0), written so that NaN propagates.
inline float16 shrink(float16 v, float kappa)
{
    const float16 m = fabs(v) - kappa;
    return copysign(select(m, (float16)0.0f, m < 0.0f), v);
}

__kernel void soft_threshold(__global const float *v, __global float *out,
                             const float kappa, const ulong n)
{
    const ulong k = get_global_id(0);
    if (k * LANES >= n) return;
    store_chunk(shrink(load_chunk(v, k, n), kappa), out, k, n);
}

// In place: z <- S_kappa(dx + u), u <- dx + u - z; dz <- z_new - z_old.
// dz may be dx (read first), never z or u.
__kernel void zu_update(__global const float *dx, __global float *z, __global float *u,
                        __global float *dz, const float kappa, const ulong n)
{
    const ulong k = get_global_id(0);
    if (k * LANES >= n) return;
    const float16 v = load_chunk(dx, k, n) + load_chunk(u, k, n);
    const float16 z_old = load_chunk(z, k, n);
    const float16 z_new = shrink(v, kappa);
    store_chunk(z_new, z, k, n);
    store_chunk(v - z_new, u, k, n);
    store_chunk(z_new - z_old, dz, k, n);
}
