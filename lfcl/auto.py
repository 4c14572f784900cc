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

The losses can be judged on both views (the worse of the two, the default) or on one of
them: the file holds a rule for each (``VIEWS``), and a run that writes only the centre
view, or only the mean image and refocused images, takes the rule fitted to that
(:func:`view_for_outputs`): which method is best differs between the two views.
For the mean image the file also holds a rule fitted on content like the real light
fields (``low_ratio``): a raw whose cross-lens ratio (lfcl/lens_ratio.py) lies below
its bound takes that one (:func:`content_class`).

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
#: What a rule's losses are judged on: the worse of the centre view and the mean image, or one of them.
VIEWS = ("both", "center", "mean")
VIEW_WORDS = {"both": "centre view or mean image, whichever is worse", "center": "centre view",
              "mean": "mean image"}
#: The content classes of a rule file: the default rule, and (``low_ratio``, for some views) a rule
#: fitted on raws whose cross-lens ratio (lfcl/lens_ratio.py) lies below LOW_RATIO_BELOW: the real
#: light fields measured 1.1-2.2, every synthetic training scene 3.0 and up (docs/auto.md).
CONTENTS = ("default", "low-ratio")
LOW_RATIO_BELOW = 2.6
#: Outputs that the mean image speaks for: a refocused image is a shifted mean over the views.
MEAN_LIKE_OUTPUTS = frozenset({"mean", "refocus"})


def view_for_outputs(outputs) -> str:
    """The rule (``VIEWS``) for a run writing ``outputs`` (lfcl.outputs.KINDS): ``center`` alone takes the
    centre-view rule, ``mean`` and ``refocus`` alone the mean-image rule, anything else (the views, the
    light field, a centre view and a mean image together) the rule judged on both."""
    kinds = set(outputs)
    if kinds == {"center"}:
        return "center"
    if kinds and kinds <= MEAN_LIKE_OUTPUTS:
        return "mean"
    return "both"


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
    view: str = "both"  # the rule's losses were judged on this view (VIEWS)
    content: str = "default"  # the content class whose rule chose (CONTENTS)

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def check_view(view: str) -> str:
    if view not in VIEWS:
        raise ValueError(f"auto's view must be one of {', '.join(VIEWS)}, got {view!r}")
    return view


@functools.lru_cache(maxsize=1)
def load_rules() -> dict:
    """The shipped rule file (lfcl/data/auto_rule.json): ``rule`` (judged on both views),
    ``rules_by_view`` and, where it was fitted, ``low_ratio`` (:func:`rule_bands`)."""
    return json.loads(resources.files("lfcl.data").joinpath(RULE_FILE).read_text())


def rule_bands(rules: dict, view: str = "both", content: str = "default") -> tuple[dict, ...] | None:
    """The sigma bands of a rule file's contents ``rules`` for ``view`` and ``content`` (``CONTENTS``),
    lowest first; None where it holds none."""
    if content == "low-ratio":
        bands = (rules.get("low_ratio") or {}).get("rules_by_view", {}).get(view)
    else:
        bands = rules["rule"] if view == "both" else rules.get("rules_by_view", {}).get(view)
    return tuple(sorted(bands, key=lambda b: b["sigma_from"])) if bands else None


def content_class(rules: dict, view: str, lens_ratio: float | None) -> str:
    """``low-ratio`` where ``rules`` hold a rule fitted on content like the real light fields for
    ``view`` and the raw's cross-lens ratio lies below the class's bound; else ``default``."""
    low = rules.get("low_ratio") or {}
    if lens_ratio is not None and view in low.get("rules_by_view", {}) and lens_ratio < low["below"]:
        return "low-ratio"
    return "default"


def load_rule(view: str = "both", content: str = "default") -> tuple[dict, ...]:
    """The shipped sigma bands of the rule for ``view`` (``VIEWS``) and ``content``, lowest first."""
    bands = rule_bands(load_rules(), check_view(view), content)
    if not bands:
        raise ValueError(f"lfcl/data/{RULE_FILE} holds no {content} rule for view {view!r}: refit it with "
                         "python -m lfcl.bench.auto_rule")
    return bands


def parse_candidate(name: str) -> tuple[str, float, str]:
    """'method[@strength][:start]' -> (method, strength, start).

    'admm-uv@2' -> ('admm-uv', 2.0, 'malvar'); 'admm-uv-xc@1:linear4d' -> ('admm-uv-xc', 1.0, 'linear4d');
    'malvar' -> ('malvar', 1.0, 'malvar').
    """
    name, _, start = name.partition(":")
    method, _, strength = name.partition("@")
    return method, float(strength) if strength else 1.0, start or "malvar"


def band_for(sigma: float, rule=None, view: str = "both") -> tuple[dict, str]:
    """The band of ``rule`` (default: the shipped one for ``view``) that holds ``sigma``, or the nearest,
    and where it lies."""
    bands = load_rule(view) if rule is None else tuple(sorted(rule, key=lambda b: b["sigma_from"]))
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
                     "malvar", choice.lens_ratio, choice.seen_content, choice.view, choice.content)
    return ran, {"method": choice.method, "strength": choice.strength, "start": choice.start, "why": why}


def for_pitch(choice: AutoChoice, pitch) -> tuple[AutoChoice, dict | None]:
    """``choice`` and None if it runs on lenses of ``pitch``, else :func:`replacement`'s pair:
    linear4d (as the method or the start, the guarded start included) has coefficients for one pitch only."""
    if "linear4d" not in (choice.method, choice.start) and choice.start != "guarded":
        return choice, None
    from .ops.linear4d import load_model

    fitted, pitch = tuple(load_model().pitch), tuple(int(p) for p in pitch)
    if pitch == fitted:
        return choice, None
    why = f"linear4d has coefficients for {fitted[0]}x{fitted[1]} lenses only, not {pitch[0]}x{pitch[1]}"
    return replacement(choice, why, *((AUTO_FALLBACK, 1.0) if choice.method == "linear4d" else ()))


def choose(sigma: float, rule=None, lens_ratio: float | None = None, view: str = "both",
           rules: dict | None = None) -> AutoChoice:
    """The method and strength for noise level ``sigma``: from the sigma bands ``rule`` if given, else
    from the rule file's contents ``rules`` (default: the shipped file), its rule for ``view``
    (``VIEWS``: what its losses were judged on) and the raw's content class (:func:`content_class`).

    ``lens_ratio``: the raw's cross-lens ratio (lfcl/lens_ratio.py). Below the ``low_ratio`` bound
    of a file that holds a rule for such content for ``view``, that rule chooses; and when the
    ratio lies outside what the band's training captures spanned, the reason says that the rule
    has not seen such content.
    """
    if not (isinstance(sigma, (int, float)) and math.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"auto needs a finite noise level >= 0, got {sigma!r}")
    check_view(view)
    content = "default"
    if rule is None:
        rules = load_rules() if rules is None else rules
        content = content_class(rules, view, lens_ratio)
        rule = rule_bands(rules, view, content)
        if not rule:
            raise ValueError(f"the auto rule holds no rule for view {view!r}: refit it with "
                             "python -m lfcl.bench.auto_rule")
    band, where = band_for(sigma, rule)
    method, strength, start = parse_candidate(band["candidate"])
    reason = (f"sigma {sigma:.3g} {where} {band['sigma_from']:.3g}-{band['sigma_to']:.3g}: on its "
              f"{band['captures']} training captures {band['candidate']} was the cheapest candidate within "
              f"{band['within_db']:g} dB of the smallest worst-case and mean PSNR loss ({VIEW_WORDS[view]}) "
              f"against the best fixed method (its losses: {band['worst_loss_db']:.2f} dB worst"
              + (f", {band['mean_loss_db']:.2f} dB mean)" if "mean_loss_db" in band else ")"))
    if content == "low-ratio":
        low = rules["low_ratio"]
        reason = (f"the raw's cross-lens ratio {lens_ratio:.2f} lies below {low['below']:g}, like the real light "
                  f"fields of docs/auto.md, so the rule fitted on such content ({', '.join(low['fitted_on'])}) "
                  f"chose; " + reason)
    seen = None
    trained = band.get("lens_ratio_range")
    if lens_ratio is not None and trained:
        seen = trained[0] <= lens_ratio <= trained[1]
        if not seen:
            reason += (f"; the raw's cross-lens ratio {lens_ratio:.2f} lies outside the {trained[0]:.2f}-"
                       f"{trained[1]:.2f} of those captures, so the rule has not seen such content")
            if content == "default":
                reason += (f" (on raws simulated from two real light fields, ratios {REAL_CONTENT_RATIOS}, the "
                           f"rule for both views lost {REAL_CONTENT_LOSS} to the best fixed method: docs/auto.md)")
    return AutoChoice(method, strength, float(sigma), reason, start, lens_ratio, seen, view, content)
