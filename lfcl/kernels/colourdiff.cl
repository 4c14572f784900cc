// The colour differences C x = (x_R - x_G, x_B - x_G) and their adjoint, per pixel (lfcl/ops/crosschannel.py
// ColourDifferences; twins colour_differences_np, colour_differences_adjoint_np):
//
//   colour_differences:          y[0] = x[0] - x[1],  y[1] = x[2] - x[1]     [3, n] -> [2, n]
//   colour_differences_adjoint:  x (+)= (y[0], -y[0] - y[1], y[1])           [2, n] -> [3, n]
//
// n = H W floats per plane, in chunks of 16 (common.cl load_chunk / store_chunk); get_global_id(1) picks one
// of a batch of such images ([B, 3, n] <-> [B, 2, n]: the u and v halves of an EPI gradient). Global size:
// (ceil(n / 16) rounded up (lfcl/ops/linalg.py elementwise_size), B).

__kernel void colour_differences(__global const float *x, __global float *y, const ulong n)
{
    const ulong k = get_global_id(0);
    if (k * LANES >= n) return;
    x += 3 * n * get_global_id(1);
    y += 2 * n * get_global_id(1);
    const float16 green = load_chunk(x + n, k, n);
    store_chunk(load_chunk(x, k, n) - green, y, k, n);
    store_chunk(load_chunk(x + 2 * n, k, n) - green, y + n, k, n);
}

__kernel void colour_differences_adjoint(__global const float *y, __global float *x, const ulong n,
                                         const int accumulate)
{
    const ulong k = get_global_id(0);
    if (k * LANES >= n) return;
    y += 2 * n * get_global_id(1);
    x += 3 * n * get_global_id(1);
    const float16 red = load_chunk(y, k, n), blue = load_chunk(y + n, k, n), green = -red - blue;
    if (accumulate) {
        store_chunk(load_chunk(x, k, n) + red, x, k, n);
        store_chunk(load_chunk(x + n, k, n) + green, x + n, k, n);
        store_chunk(load_chunk(x + 2 * n, k, n) + blue, x + 2 * n, k, n);
    } else {
        store_chunk(red, x, k, n);
        store_chunk(green, x + n, k, n);
        store_chunk(blue, x + 2 * n, k, n);
    }
}
