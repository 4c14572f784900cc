"""What ``--method auto`` skipped, and why: entries for the ``skipped`` list of `lfcl process` (docs/outputs.md).

``auto`` (lfcl/demosaic/auto.py) picks, in the noise band of the raw, the candidate of the best worst-case PSNR
gain over Malvar on its training captures (within ``tie_db``, the largest median gain). Candidates with a
better worst case or a better median than the chosen one were skipped, because they lose more elsewhere
or gain less in the middle; the band's figures (lfcl/data/auto_rule.json) say by how much.
On a resampled lens grid a method the rule names but that does not run there is replaced
(lfcl/demosaic/resampled.py, ``parameters["auto"]["replaced"]``); that is listed too.

Example::

    >>> rule = [{"sigma_from": 0.0, "sigma_to": 1.0, "candidate": "malvar", "tie_db": 0.1, "captures": 4,
    ...          "worst_gains_db": {"malvar": 0.0, "admm-uv@1": -0.5}, "median_gains_db": {"malvar": 0.0, "admm-uv@1": 2.0},
    ...          "median_seconds": {"malvar": 0.01, "admm-uv@1": 0.2}}]
    >>> [s["output"] for s in skipped_by_auto({"method": "malvar", "sigma": 0.003}, rule)]
    ['admm-uv@1']
"""

from __future__ import annotations

from .auto import band_for, is_costly, load_rule


def skipped_by_auto(auto: dict | None, rule=None) -> list[dict]:
    """``{"output", "stage", "reason"}`` per candidate that ``auto`` (``parameters["auto"]``) skipped; [] without auto."""
    if not auto:
        return []
    skipped = []
    replaced = auto.get("replaced")
    if replaced:
        skipped.append({"output": replaced["method"], "stage": "demosaic",
                        "reason": f"auto's rule names it, but {replaced.get('why', 'it does not run here')}: "
                                  f"{auto['method']} instead"})
        return skipped  # the rule's other candidates were weighed against a method that did not run
    if auto.get("sigma") is None:  # a frame too small for any prior (lfcl.demosaic.auto.small_frame): no rule ran
        return [{"output": "the priors", "stage": "demosaic", "reason": f"auto ran Malvar on {auto['reason']}"}]
    if rule is None:  # the shipped rule that chose, for its view
        rule = load_rule(auto.get("view", "both"))
    band, _ = band_for(float(auto["sigma"]), rule)
    chosen = band["candidate"]
    worst, median = band.get("worst_gains_db", {}), band.get("median_gains_db", {})
    seconds = band.get("median_seconds", {})
    if chosen not in worst:
        return skipped
    for name in sorted(worst, key=lambda n: -worst[n]):
        if name == chosen or not (worst[name] > worst[chosen] or median.get(name, -1e9) > median.get(chosen, -1e9)):
            continue
        cost = (f", median {seconds[chosen]:.2f} s against {seconds[name]:.2f} s"
                if chosen in seconds and name in seconds else "")
        figures = (f"worst-case gain over Malvar {worst[chosen]:+.2f} dB against {worst[name]:+.2f} dB, median "
                   f"{median.get(chosen, float('nan')):+.2f} dB against {median.get(name, float('nan')):+.2f} dB")
        if is_costly(name) and not is_costly(chosen) and "costly_margin_db" in band:
            why = (f"a costly method takes a band only where its worst case beats the cheap pick's by "
                   f"{band['costly_margin_db']:g} dB, and darker bands where it is no worse")
        else:
            why = f"ties within {band['tie_db']:g} dB go to the larger median"
        skipped.append({"output": name, "stage": "demosaic",
                        "reason": f"auto chose {chosen}: {figures} ({why}){cost} on {band['captures']} training "
                                  "captures"})
    return skipped
