"""``--method auto``: choose the method and the lambda strength from the raw's noise level.

The choice is a table over bands of sigma (rms noise per raw pixel, normalised
units; from the DNG NoiseProfile or estimated from the raw, lfcl/noise.py),
shipped as lfcl/data/auto_rule.json. ``python -m lfcl.bench.auto_rule`` fitted it
on training captures (seeds other than the evaluation seed): in each band it
holds the cheapest candidate (method and lambda strength) whose worst PSNR loss
(centre view or mean image) against the best fixed method came within 0.1 dB of
the smallest such loss, and whose mean loss came within 0.1 dB of the smallest
mean loss of those. A sigma outside the trained range takes the nearest
band, and the reason says so.

Example::

    >>> from lfcl.auto import choose
    >>> choice = choose(0.0046)
    >>> choice.method in ("malvar", "admm-uv", "admm-uvst", "admm-uv-xc", "linear4d")
    True
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from importlib import resources

RULE_FILE = "auto_rule.json"
#: What ``auto`` runs when the rule names a method that cannot run on the raw at hand (linear4d
#: on a pitch without coefficients, a method a resampled grid lacks): the method that gained
#: over malvar on every setting measured (docs/admm.md, docs/geometry.md), at strength 1.
AUTO_FALLBACK = "admm-uv"
#: What docs/auto.md measured on raws simulated from the two real light fields (antinous, Lytro 2067),
#: quoted when a raw's content lies outside the rule's training captures.
REAL_CONTENT_RATIOS = "1.1-2.2"
REAL_CONTENT_LOSS = "0.3-2.5 dB"


@dataclasses.dataclass(frozen=True)
class AutoChoice:
    """What ``auto`` chose for one raw, and why (goes into the outputs' metadata)."""

    method: str
    strength: float
    sigma: float
    reason: str
    start: str = "malvar"  # the ADMM methods' first estimate (lfcl.methods.STARTS)
    # the raw's cross-lens ratio (lfcl/lens_ratio.py; None: not measured or not significant) and
    # whether the band's training captures spanned it (None: unknown)
    lens_ratio: float | None = None
    seen_content: bool | None = None

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


@functools.lru_cache(maxsize=1)
def load_rule() -> tuple[dict, ...]:
    """The shipped sigma bands, lowest first."""
    text = resources.files("lfcl.data").joinpath(RULE_FILE).read_text()
    bands = json.loads(text)["rule"]
    if not bands:
        raise ValueError(f"lfcl/data/{RULE_FILE} holds no rule: refit it with python -m lfcl.bench.auto_rule")
    return tuple(sorted(bands, key=lambda b: b["sigma_from"]))


def parse_candidate(name: str) -> tuple[str, float, str]:
    """'method[@strength][:start]' -> (method, strength, start).

    'admm-uv@2' -> ('admm-uv', 2.0, 'malvar'); 'admm-uv-xc@1:linear4d' -> ('admm-uv-xc', 1.0, 'linear4d');
    'malvar' -> ('malvar', 1.0, 'malvar').
    """
    name, _, start = name.partition(":")
    method, _, strength = name.partition("@")
    return method, float(strength) if strength else 1.0, start or "malvar"


def band_for(sigma: float, rule=None) -> tuple[dict, str]:
    """The band of ``rule`` (default: the shipped one) that holds ``sigma``, or the nearest, and where it lies."""
    bands = load_rule() if rule is None else tuple(sorted(rule, key=lambda b: b["sigma_from"]))
    inside = [b for b in bands if b["sigma_from"] <= sigma < b["sigma_to"]]
    if inside:
        return inside[0], "in"
    if sigma < bands[0]["sigma_from"]:
        return bands[0], "below the trained range; nearest band"
    return bands[-1], "above the trained range; nearest band"


def replacement(choice: AutoChoice, why: str, method: str | None = None, strength: float | None = None
                ) -> tuple[AutoChoice, dict]:
    """What runs instead of ``choice``, which cannot run here (``why``): ``method`` (default: the
    choice's) at ``strength`` (default: the choice's) from the Malvar start; and the ``replaced``
    entry of ``parameters["auto"]`` (lfcl/auto_report.py lists it)."""
    method = choice.method if method is None else method
    strength = choice.strength if strength is None else strength
    at = f" at strength {strength:g}" if strength != 1 else ""
    ran = AutoChoice(method, strength, choice.sigma, f"{choice.reason}; {why}, so {method}{at} from a Malvar start",
                     "malvar", choice.lens_ratio, choice.seen_content)
    return ran, {"method": choice.method, "strength": choice.strength, "start": choice.start, "why": why}


def for_pitch(choice: AutoChoice, pitch) -> tuple[AutoChoice, dict | None]:
    """``choice`` and None if it runs on lenses of ``pitch``, else :func:`replacement`'s pair:
    linear4d (as the method or the start) has coefficients for one pitch only."""
    if "linear4d" not in (choice.method, choice.start):
        return choice, None
    from .ops.linear4d import load_model

    fitted, pitch = tuple(load_model().pitch), tuple(int(p) for p in pitch)
    if pitch == fitted:
        return choice, None
    why = f"linear4d has coefficients for {fitted[0]}x{fitted[1]} lenses only, not {pitch[0]}x{pitch[1]}"
    return replacement(choice, why, *((AUTO_FALLBACK, 1.0) if choice.method == "linear4d" else ()))


def choose(sigma: float, rule=None, lens_ratio: float | None = None) -> AutoChoice:
    """The method and strength for noise level ``sigma``.

    ``lens_ratio``: the raw's cross-lens ratio (lfcl/lens_ratio.py). It does not change the
    choice; when it lies outside what the band's training captures spanned, the reason says
    that the rule has not seen such content.
    """
    if not (isinstance(sigma, (int, float)) and math.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"auto needs a finite noise level >= 0, got {sigma!r}")
    band, where = band_for(sigma, rule)
    method, strength, start = parse_candidate(band["candidate"])
    reason = (f"sigma {sigma:.3g} {where} {band['sigma_from']:.3g}-{band['sigma_to']:.3g}: on its "
              f"{band['captures']} training captures {band['candidate']} was the cheapest candidate within "
              f"{band['within_db']:g} dB of the smallest worst-case and mean PSNR loss against the best fixed "
              f"method (its losses: {band['worst_loss_db']:.2f} dB worst"
              + (f", {band['mean_loss_db']:.2f} dB mean)" if "mean_loss_db" in band else ")"))
    seen = None
    trained = band.get("lens_ratio_range")
    if lens_ratio is not None and trained:
        seen = trained[0] <= lens_ratio <= trained[1]
        if not seen:
            reason += (f"; the raw's cross-lens ratio {lens_ratio:.2f} lies outside the {trained[0]:.2f}-"
                       f"{trained[1]:.2f} of those captures, so the rule has not seen such content (on raws "
                       f"simulated from two real light fields, ratios {REAL_CONTENT_RATIOS}, it lost "
                       f"{REAL_CONTENT_LOSS} to the best fixed method: docs/auto.md)")
    return AutoChoice(method, strength, float(sigma), reason, start, lens_ratio, seen)
