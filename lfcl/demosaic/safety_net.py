"""The safety net: no lens's colour means stray from Malvar's further than the noise explains.

"Never worse than Malvar" (issue 18). The (u, v) priors see one lens at a time, so each lens's
colour means come from its own ~20 red, 40 green and 20 blue samples, where Malvar's also read the
neighbouring lenses' samples: on natural light fields (the real ``antinous`` and Lytro ``2067``)
that alone cost admm-uv 0.7-1.7 dB of mean-image PSNR against Malvar at every light level
(docs/auto.md, "The safety net"). No per-lens statistic of the result against the raw or against
Malvar told those lenses from the ones where the prior is right (measured there: the residual
``A x - b`` stays far below the noise everywhere, and the disagreement with Malvar is as large on
charts, where admm-uv gains 3 dB, as on the Lytro frame, where it loses).

What does separate them is how far the two *lens means* lie apart in units of the noise of a lens
mean: within the noise, Malvar's is the better estimate (it averages more samples); far beyond it,
Malvar's read a different micro-image across a lens border and the method's is the better one. So
each lens's colour mean is soft-thresholded towards Malvar's at ``NET_K`` noise sds (kernels
``guard_lens_means``, lfcl/ops/lensguard.py): a lens whose means agree within the noise takes
Malvar's means, one that disagrees keeps its own, moved by ``NET_K`` sds. The texture inside every
lens is the method's own.

One kind of lens has a better reference than Malvar's: a lens flat within the noise (the chi-square test of
lfcl/demosaic/flat_lenses.py: one colour per channel, as an in-focus patch is) whose Malvar colour mean lies more
than ``FLAT_J`` sds from the mean of its own samples of that colour. Its micro-image is one colour, so its own
samples' means are the unbiased estimate of it, and Malvar's can only have moved that far by reading a different
micro-image across the lens border: in-focus content that changes at the lens scale (a grating of 2.5 lenses, a
checker of 1-2 lens squares), where the net pulled every lens towards Malvar's wrong means and put the default
2-29 dB below Malvar's centre view (docs/auto.md, "Flat lenses the net fills"). Such a lens is filled with its own
colour means. It runs on the device after any method but Malvar (after admm-epi the fill alone: ``NET_K_BY_METHOD``);
its work is one pass over the planes and one over the mosaic (BENCHMARKS.md).
"""

from __future__ import annotations

import numpy as np

from ..noise.model import NoiseEstimate
from ..ops.lensguard import LensGuard
from ..ops.malvar import Malvar
from .flat_lenses import flat_lenses_on_device

#: Lens colour means further than this many noise sds of a lens mean from Malvar's are the method's own
#: (moved by this much); nearer ones are Malvar's. research/fit_safety_net.py on the training captures
#: (charts, deadleaves, finetexture at seeds 1 and 2, four training photographs): the best worst case over
#: admm-uv, admm-uvst and admm-uv-xc, -0.02 dB (k = 3: -0.25, no net: -0.79; docs/auto.md).
NET_K = 8.0
#: Methods with their own threshold, fitted the same way (``research/fit_safety_net.py --methods M``); inf: no soft
#: threshold, the method keeps its lens means (only flat lenses are filled, ``FLAT_J``). admm-epi averages each colour
#: along the epipolar lines over ~81 samples of many lenses, so its lens means are better than Malvar's where they
#: agree within the noise: on the training captures every finite k replaced them and cost the median mean image
#: 1.6 dB and the median centre view 0.5 dB, for no better worst case (+0.00 dB at k = 3-32, +0.03 without the net;
#: docs/auto.md).
NET_K_BY_METHOD = {"admm-epi": float("inf")}
#: A flat lens whose Malvar colour mean lies further than this many noise sds of a lens mean from its own samples'
#: mean is filled with its own means (module docstring); every method. research/fit_safety_net.py at NET_K on the same
#: training captures: of the j that leave the worst case no lower than the net without filling (-0.04 dB), the
#: largest median mean-image gain, +0.52 dB against +0.00 (0.5 sd: worst -0.07, 0 sd, every flat lens: -0.25, the
#: training photographs' mean image at 0.5 lux). For admm-epi (``--methods admm-epi``, no soft threshold): 0.5 and 1
#: sd tie (worst +0.70 dB as without, median mean image +3.17 against +3.08), and a tie goes to the larger j
#: (docs/auto.md "Flat lenses the net fills").
FLAT_J = 1.0


def net_k(method: str) -> float:
    """The safety net's threshold for ``method`` (inf: no soft threshold, only the flat lenses' fill)."""
    return NET_K_BY_METHOD.get(method, NET_K)


def apply_safety_net(runtime, planes: np.ndarray, mosaic: np.ndarray, pattern: str, pitch, origin,
                     noise: NoiseEstimate, k: float = NET_K, lens_weights=None,
                     j: float = FLAT_J) -> tuple[np.ndarray, dict]:
    """``planes`` [3, H, W] (host) with the lens-mean guard applied against Malvar of ``mosaic``; what it did.

    ``lens_weights`` [U, V]: the flat field's data-term weights (None: every pixel lit), for the flat-lens test.
    """
    x = runtime.to_device(np.ascontiguousarray(planes, dtype=np.float32))
    b = runtime.to_device(np.ascontiguousarray(mosaic, dtype=np.float32))
    malvar = Malvar(runtime, mosaic.shape, pattern, origin).forward(b)
    found = flat_lenses_on_device(runtime, b, mosaic, pattern, pitch, noise, origin=origin, lens_weights=lens_weights)
    replaced = LensGuard(runtime, mosaic.shape, pitch).guard_means(x, malvar, b, noise.gain, noise.floor, k,
                                                                  found.flat, found.means, j)
    out = x.get()
    filled = int(np.count_nonzero(replaced < 0))
    fill_why = (f"a lens flat within the noise whose Malvar mean lies more than {j:g} sds from its own samples' takes "
                f"its own colour means (lfcl/demosaic/safety_net.py)")
    if np.isinf(k):
        why = f"no soft threshold (the method's lens means are its own, fitted per method); {fill_why}"
    else:
        why = (f"each lens colour mean within {k:g} noise sds of a lens mean of Malvar's takes Malvar's; the others "
               f"move {k:g} sds towards it; {fill_why}")
    report = {
        "k": None if np.isinf(k) else k,  # JSON has no Infinity
        "flat_j": j,
        "lenses": int(replaced.size),
        "lenses_from_malvar": int(np.count_nonzero(replaced == 3)),
        "lenses_kept": int(np.count_nonzero(replaced == 0)),
        "lenses_filled_flat": filled,
        "colour_means_from_malvar": int(replaced[replaced > 0].sum()),
        "why": why,
    }
    return out, report
