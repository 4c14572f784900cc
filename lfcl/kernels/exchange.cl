// Colour planes -> the exchange light field, on the device (lfcl/ops/exchange.py; twin:
// lfcl.layout.planes_to_exchange). The demosaic works on planes [3, S*U, T*V]; users and the
// output files take [S, T, U, V, 3] (docs/layout.md). Transposing 60 M floats on the host cost
// more than the Malvar demosaic itself (BENCHMARKS.md, "lfcl bench api"), so the device writes
// the exchange layout and the host downloads it as it is.
//
// Built with -DPITCH_U=U -DPITCH_V=V (constant divisions). Global size (T*V, S*U): one
// work-item per sensor pixel, reading its three planes and writing its three colours side by side.

__kernel void planes_to_exchange(__global const float *planes, __global float *lightfield,
                                 const int height, const int width)
{
    const int col = get_global_id(0), row = get_global_id(1);
    if (col >= width || row >= height) return;
    const int s = row / PITCH_U, u = row % PITCH_U, t = col / PITCH_V, v = col % PITCH_V;
    const int T = width / PITCH_V;
    const size_t plane = (size_t)height * width, i = (size_t)row * width + col;
    const size_t o = 3 * ((((size_t)s * T + t) * PITCH_U + u) * PITCH_V + v);
    lightfield[o] = planes[i];
    lightfield[o + 1] = planes[plane + i];
    lightfield[o + 2] = planes[2 * plane + i];
}
