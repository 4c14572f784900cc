"""What ``--method auto`` skipped, and why: entries for the ``skipped`` list of `lfcl process` (docs/outputs.md).

``auto`` (lfcl/auto.py) picks, in the noise band of the raw, the *cheapest* candidate whose
worst-case and mean PSNR losses on the training captures came within ``within_db`` of the
smallest. Candidates with a smaller worst-case or mean loss than the chosen one were skipped,
to save time or because they lose more elsewhere; the band's training rows
(lfcl/data/auto_rule.json) say by how much.
On a resampled lens grid a method the rule names but that does not run there is replaced
(lfcl/grid_demosaic.py, ``parameters["auto"]["replaced"]``); that is listed too.

Example::

    >>> rule = [{"sigma_from": 0.0, "sigma_to": 1.0, "candidate": "malvar", "within_db": 0.1, "captures": 4,
    ...          "losses_db": {"malvar": 0.05, "admm-uv@1": 0.0},
    ...          "median_seconds": {"malvar": 0.01, "admm-uv@1": 0.2}}]
    >>> [s["output"] for s in skipped_by_auto({"method": "malvar", "sigma": 0.003}, rule)]
    ['admm-uv@1']
"""

from __future__ import annotations

from .auto import band_for, load_rule


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
    if rule is None:  # the shipped rule that chose: its view and content class
        rule = load_rule(auto.get("view", "both"), auto.get("content", "default"))
    band, _ = band_for(float(auto["sigma"]), rule)
    chosen = band["candidate"]
    losses, seconds = band.get("losses_db", {}), band.get("median_seconds", {})
    means = band.get("mean_losses_db", {})
    if chosen not in losses:
        return skipped
    for name, loss in sorted(losses.items(), key=lambda item: item[1]):
        better_mean = chosen in means and name in means and means[name] < means[chosen]
        if name == chosen or not (loss < losses[chosen] or better_mean):
            continue
        cheaper = chosen in seconds and name in seconds and seconds[chosen] < seconds[name]
        mean = f", mean {means[chosen]:.2f} dB against {means[name]:.2f} dB" if chosen in means and name in means else ""
        cost = (f", median {seconds[chosen]:.2f} s against {seconds[name]:.2f} s"
                if chosen in seconds and name in seconds else "")
        skipped.append({"output": name, "stage": "demosaic",
                        "reason": f"auto chose {'the cheaper ' if cheaper else ''}{chosen}: worst-case PSNR loss "
                                  f"{losses[chosen]:.2f} dB against {loss:.2f} dB{mean} (within "
                                  f"{band['within_db']:g} dB){cost} on {band['captures']} training captures"})
    return skipped
