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
lens is the method's own. It runs on the device after any method but Malvar; its work is one pass
over the planes (BENCHMARKS.md).
"""

from __future__ import annotations

import numpy as np

from ..noise.model import NoiseEstimate
from ..ops.lensguard import LensGuard
from ..ops.malvar import Malvar

#: Lens colour means further than this many noise sds of a lens mean from Malvar's are the method's own
#: (moved by this much); nearer ones are Malvar's. research/fit_safety_net.py on the training captures
#: (charts, deadleaves, finetexture at seeds 1 and 2, four training photographs): the best worst case over
#: admm-uv, admm-uvst and admm-uv-xc, -0.02 dB (k = 3: -0.25, no net: -0.79; docs/auto.md).
NET_K = 8.0
#: Methods with their own threshold, fitted the same way (``research/fit_safety_net.py --methods M``); inf: the net
#: does not run. admm-epi averages each colour along the epipolar lines over ~81 samples of many lenses, so its lens
#: means are better than Malvar's where they agree within the noise: on the training captures every finite k
#: replaced them and cost the median mean image 1.6 dB and the median centre view 0.5 dB, for no better worst case
#: (+0.00 dB at k = 3-32, +0.03 without the net; docs/auto.md).
NET_K_BY_METHOD = {"admm-epi": float("inf")}


def net_k(method: str) -> float:
    """The safety net's threshold for ``method`` (inf: the net does not run for it)."""
    return NET_K_BY_METHOD.get(method, NET_K)


def apply_safety_net(runtime, planes: np.ndarray, mosaic: np.ndarray, pattern: str, pitch, origin,
                     noise: NoiseEstimate, k: float = NET_K) -> tuple[np.ndarray, dict]:
    """``planes`` [3, H, W] (host) with the lens-mean guard applied against Malvar of ``mosaic``; what it did."""
    x = runtime.to_device(np.ascontiguousarray(planes, dtype=np.float32))
    b = runtime.to_device(np.ascontiguousarray(mosaic, dtype=np.float32))
    malvar = Malvar(runtime, mosaic.shape, pattern, origin).forward(b)
    replaced = LensGuard(runtime, mosaic.shape, pitch).guard_means(x, malvar, b, noise.gain, noise.floor, k)
    out = x.get()
    lenses = int(replaced.size)
    report = {
        "k": k,
        "lenses": lenses,
        "lenses_from_malvar": int(np.count_nonzero(replaced == 3)),
        "lenses_kept": int(np.count_nonzero(replaced == 0)),
        "colour_means_from_malvar": int(replaced.sum()),
        "why": f"each lens colour mean within {k:g} noise sds of a lens mean of Malvar's takes Malvar's; "
               f"the others move {k:g} sds towards it (lfcl/demosaic/safety_net.py)",
    }
    return out, report
