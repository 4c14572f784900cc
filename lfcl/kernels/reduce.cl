// Accurate reductions: sum x_i, <x, y> = sum x_i y_i and ||x||^2 = sum x_i^2 over
// n floats, with the compensated scheme Sum2 / Dot2 of Ogita, Rump & Oishi
// ("Accurate sum and dot product", SIAM J. Sci. Comput. 26, 2005).
//
// Each of G work-items keeps, in each of 16 SIMD lanes, a float pair (s, c) whose
// sum s + c is its running total to about twice float precision: s the plain
// float sum, c the float sum of every rounding error made on the way, recovered
// exactly by the error-free transformations
//
//   TwoProduct:  a * b = p + e   exactly, p = fl(a * b),  e = fma(a, b, -p)
//   TwoSum:      a + b = s + e   exactly, s = fl(a + b),  e = (a - (s - z)) + (b - z), z = s - a
//
// and per term t = x_i y_i:  (p, h) = TwoProduct(x_i, y_i), (s, q) = TwoSum(s, p), c += q + h.
// The lanes are folded into one pair per work-item; the host adds the G pairs in
// float64 (math.fsum). Work-item w owns a run of 16-float chunks: in "contiguous"
// mode the balanced run [w*K/G, (w+1)*K/G) of the K = n/16 chunks (one streaming
// read per CPU thread), in "interleaved" mode chunks w, w+G, w+2G, ... (coalesced
// on a GPU). The last n mod 16 floats go to work-item 0, zero-padded (0 adds nothing).
//
// Output: partial[2w] = s, partial[2w + 1] = c. Global size: (G), any local size.

// The error-free transformations need every product and sum rounded on its own.
#pragma OPENCL FP_CONTRACT OFF


// a + b = s + *e exactly (Knuth's TwoSum: no branch, any order of magnitude).
inline float16 two_sum(float16 a, float16 b, float16 *e)
{
    const float16 s = a + b;
    const float16 z = s - a;
    *e = (a - (s - z)) + (b - z);
    return s;
}

// a * b = p + *e exactly (TwoProduct by one fused multiply-add).
inline float16 two_product(float16 a, float16 b, float16 *e)
{
    const float16 p = a * b;
    *e = fma(a, b, -p);
    return p;
}

// (s, c) += t + t_err: s takes the rounded sum, c every error made.
inline void accumulate(float16 *s, float16 *c, float16 t, float16 t_err)
{
    float16 q;
    *s = two_sum(*s, t, &q);
    *c += q + t_err;
}

// Fold the 16 lane pairs into lane 0: add the pairs `shift` lanes up (mod 16), for
// shift = 8, 4, 2, 1. Lane 0 then holds the work-item's total as s.s0 + c.s0.
inline void fold_lanes(float16 *s, float16 *c)
{
    const uint16 lane = (uint16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    for (uint shift = LANES / 2; shift > 0; shift /= 2) {
        const uint16 up = (lane + shift) % LANES;
        const float16 s_up = shuffle(*s, up), c_up = shuffle(*c, up);
        accumulate(s, c, s_up, c_up);
    }
}

// The chunk run [*first, *end) with stride *step owned by work-item w of G.
inline void chunk_run(ulong chunks, ulong w, ulong G, int interleaved,
                      ulong *first, ulong *end, ulong *step)
{
    if (interleaved) {
        *first = w, *end = chunks, *step = G;
    } else {
        *first = w * chunks / G, *end = (w + 1) * chunks / G, *step = 1;
    }
}

inline void store_partial(__global float *partial, ulong w, float16 s, float16 c)
{
    fold_lanes(&s, &c);
    partial[2 * w] = s.s0;
    partial[2 * w + 1] = c.s0;
}

// The body every reduction shares: work-item w accumulates TERM(k) over its chunk
// run (work-item 0 also takes the short last chunk); TERM sets the chunk's term p
// and that term's exact rounding error h.
#define REDUCE_CHUNKS(TERM)                                                   \
    const ulong w = get_global_id(0), G = get_global_size(0);                 \
    const ulong chunks = n / LANES;                                           \
    ulong k, end, step;                                                       \
    chunk_run(chunks, w, G, interleaved, &k, &end, &step);                    \
    float16 s = (float16)0.0f, c = (float16)0.0f, p, h;                       \
    for (; k < end; k += step) { TERM(k); accumulate(&s, &c, p, h); }        \
    if (w == 0 && chunks * LANES < n) { TERM(chunks); accumulate(&s, &c, p, h); } \
    store_partial(partial, w, s, c)

// sum_i x_i y_i
#define DOT_TERM(k) p = two_product(load_chunk(x, k, n), load_chunk(y, k, n), &h)
__kernel void dot_partials(__global const float *x, __global const float *y, const ulong n,
                           const int interleaved, __global float *partial)
{
    REDUCE_CHUNKS(DOT_TERM);
}

// sum_i x_i^2
#define NORM2_TERM(k) { const float16 xk = load_chunk(x, k, n); p = two_product(xk, xk, &h); }
__kernel void norm2_partials(__global const float *x, const ulong n,
                             const int interleaved, __global float *partial)
{
    REDUCE_CHUNKS(NORM2_TERM);
}

// sum_i (x_i - y_i)^2, with d = x - y split exactly as d + e: (d + e)^2 ~ d^2 + 2 d e
#define DIFF_NORM2_TERM(k) {                                                  \
        float16 e;                                                            \
        const float16 d = two_sum(load_chunk(x, k, n), -load_chunk(y, k, n), &e); \
        p = two_product(d, d, &h);                                            \
        h += 2.0f * d * e;                                                    \
    }
__kernel void diff_norm2_partials(__global const float *x, __global const float *y, const ulong n,
                                  const int interleaved, __global float *partial)
{
    REDUCE_CHUNKS(DIFF_NORM2_TERM);
}

// sum_i x_i
#define SUM_TERM(k) { p = load_chunk(x, k, n); h = (float16)0.0f; }
__kernel void sum_partials(__global const float *x, const ulong n,
                           const int interleaved, __global float *partial)
{
    REDUCE_CHUNKS(SUM_TERM);
}

// sum_i |x_i| (the l1 norm of the TV term)
#define ABS_SUM_TERM(k) { p = fabs(load_chunk(x, k, n)); h = (float16)0.0f; }
__kernel void abs_sum_partials(__global const float *x, const ulong n,
                               const int interleaved, __global float *partial)
{
    REDUCE_CHUNKS(ABS_SUM_TERM);
}
