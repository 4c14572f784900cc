"""``--method auto``: choose the method and the lambda strength from the raw's noise level and content.

The choice is a table over bands of sigma (rms noise per raw pixel, normalised units; from the DNG
NoiseProfile or estimated from the raw, lfcl/noise/model.py), shipped as lfcl/data/auto_rule.json and
fitted by research/fit_auto.py on training captures only (charts, deadleaves and finetexture at seeds
1 and 2, charts planes carrying four training photographs), every candidate run as `lfcl process`
runs it (the safety net on). In each band it holds the candidate (method, lambda strength) of the best
*worst-case* PSNR gain over Malvar on those captures, and among those within ``TIE_DB`` of it the one
of the largest median gain (:func:`fit_rule`): Malvar is a candidate, so a pick is never more than
``TIE_DB`` below Malvar on its training captures ("never worse than Malvar", docs/auto.md). A costly method
(``COSTLY_METHODS``: admm-epi) takes a band only where its worst-case gain beats the cheap pick's by
``COSTLY_MARGIN_DB``, and the darker bands where it is no worse: in low light (docs/auto.md, "admm-epi at
low light"). A sigma outside the trained range
takes the nearest band, and the reason says so.

The gains can be judged on both views (the lower of the two, the default) or on one of them: the
file holds a rule for each (``VIEWS``), and a run that writes only the centre view, or only the mean
image and refocused images, takes the rule fitted to that (:func:`view_for_outputs`). The raw's cross-lens ratio
(lfcl/demosaic/lens_ratio.py) is recorded, and the reason says when it lies outside what the band's training
captures spanned.

Example::

    >>> from lfcl.demosaic.auto import choose
    >>> choice = choose(0.0046)
    >>> choice.method in ("malvar", "admm-uv", "admm-uvst", "admm-uv-xc", "linear4d")
    True
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import json
import math
import statistics
from importlib import resources

from .names import parse_method_spec

RULE_FILE = "auto_rule.json"
#: What ``auto`` runs when the rule names linear4d on an aligned grid whose pitch it has no coefficients for, at
#: strength 1 (docs/admm.md). (A resampled grid runs Malvar: :func:`on_resampled_grid`.)
AUTO_FALLBACK = "admm-uv"
#: What a rule's losses are judged on: the worse of the centre view and the mean image, or one of them.
VIEWS = ("both", "center", "mean")
VIEW_WORDS = {"both": "centre view or mean image, whichever is worse", "center": "centre view",
              "mean": "mean image"}
#: The rule's sigma bands: this many a decade (research/fit_auto.py); candidates within TIE_DB of the best
#: worst case are ranked by their median gain.
BANDS_PER_DECADE = 4
TIE_DB = 0.1
#: Methods that cost a multiple of the others' time: admm-epi took 5.2-11.1x admm-uv's time end to end at 500x500
#: lenses on 2 CPU cores (2 and 12 lux; `lfcl bench process`, BENCHMARKS.md). A costly candidate takes a band only where its worst-case gain over
#: Malvar beats the best cheap candidate's by COSTLY_MARGIN_DB (issue 20's margin over today's best method at
#: low light), so that the time buys a gain on every training capture of the band, not on average; and the
#: darker bands where it is no worse than the cheap pick (costly_picks).
COSTLY_METHODS = ("admm-epi",)
COSTLY_MARGIN_DB = 1.0
#: Methods whose start, where a candidate names none, is their own rule's rather than Malvar: admm-epi's follows
#: its schedule (lfcl/solvers/epi.py epi_start), as research/fit_auto.py ran it.
OWN_START_METHODS = ("admm-epi",)
#: Outputs that the mean image speaks for: a refocused image is a shifted mean over the views.
MEAN_LIKE_OUTPUTS = frozenset({"mean", "refocus"})


def view_for_outputs(outputs) -> str:
    """The rule (``VIEWS``) for a run writing ``outputs`` (lfcl.outputs.files.KINDS): ``center`` alone takes the
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
    start: str | None = "malvar"  # the ADMM methods' first estimate (lfcl.demosaic.methods.STARTS); None: the method's own
    # the raw's cross-lens ratio (lfcl/demosaic/lens_ratio.py; None: not measured or not significant) and
    # whether the band's training captures spanned it (None: unknown)
    lens_ratio: float | None = None
    seen_content: bool | None = None
    view: str = "both"  # the rule's losses were judged on this view (VIEWS)
    costly: bool = True  # False: the rule fitted without COSTLY_METHODS (--auto-cheap)

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def check_view(view: str) -> str:
    if view not in VIEWS:
        raise ValueError(f"auto's view must be one of {', '.join(VIEWS)}, got {view!r}")
    return view


@functools.lru_cache(maxsize=1)
def load_rules() -> dict:
    """The shipped rule file (lfcl/data/auto_rule.json): ``rules[content][view]``, sigma bands (:func:`fit_rules`)."""
    return json.loads(resources.files("lfcl.data").joinpath(RULE_FILE).read_text())


def rule_bands(rules: dict, view: str = "both", costly: bool = True) -> tuple[dict, ...] | None:
    """The sigma bands of a rule file's contents ``rules`` for ``view``, lowest first (``costly`` False: of the
    rule fitted without :data:`COSTLY_METHODS`); None where it holds none."""
    bands = rules.get("rules" if costly else "cheap_rules", {}).get(view)
    return tuple(sorted(bands, key=lambda b: b["sigma_from"])) if bands else None


def load_rule(view: str = "both", costly: bool = True) -> tuple[dict, ...]:
    """The shipped sigma bands of the rule for ``view`` (``VIEWS``), lowest first (``costly`` False: the rule
    fitted without :data:`COSTLY_METHODS`)."""
    bands = rule_bands(load_rules(), check_view(view), costly)
    if not bands:
        raise ValueError(f"lfcl/data/{RULE_FILE} holds no rule for view {view!r}: refit it with "
                         "research/fit_auto.py")
    return bands


def row_gain(row: dict, candidate: str, view: str) -> float:
    """A training row's PSNR gain of ``candidate`` over Malvar on ``view`` (``both``: the lower of the two)."""
    if candidate == "malvar":
        return 0.0
    gains = row["gains"][candidate]
    return min(gains["center"], gains["mean"]) if view == "both" else gains[view]


def row_merit(row: dict, candidate: str, view: str) -> float:
    """What ties of the worst case are broken by: the gain on ``view``, for ``both`` the mean of the two views'
    gains (their lower one is often the mean image's, which the safety net holds at Malvar's)."""
    if candidate == "malvar" or view != "both":
        return row_gain(row, candidate, view)
    gains = row["gains"][candidate]
    return 0.5 * (gains["center"] + gains["mean"])


def _band_edges(rows) -> list[float]:
    """Contiguous sigma bands, a quarter decade wide, over the rows' noise levels: empty bands join the next."""
    logs = sorted(math.log10(max(r["sigma"], 1e-12)) for r in rows)
    lo, hi = math.floor(logs[0] * BANDS_PER_DECADE), math.floor(logs[-1] * BANDS_PER_DECADE) + 1
    edges = [10 ** (k / BANDS_PER_DECADE) for k in range(lo, hi + 1)]
    kept = [edges[0]] + [e for e in edges[1:-1] if any(e <= r["sigma"] < e * 10 ** (1 / BANDS_PER_DECADE)
                                                        for r in rows)] + [edges[-1]]
    return sorted(set(kept))


def _band(rows: list[dict], lo: float, hi: float, view: str, tie_db: float, pick: str | None = None) -> dict:
    """One band of :func:`fit_rule` over ``rows`` (those of ``[lo, hi)``): each candidate's worst and
    median gain, and the pick (``pick``, or the best worst case; within ``tie_db`` of it, the best median)."""
    candidates = ["malvar", *sorted({c for r in rows for c in r["gains"]})]
    worst, median, seconds = {}, {}, {}
    for c in candidates:
        if all(c == "malvar" or c in r["gains"] for r in rows):
            worst[c] = min(row_gain(r, c, view) for r in rows)
            median[c] = float(statistics.median(row_merit(r, c, view) for r in rows))
            seconds[c] = float(statistics.median([r["malvar"]["seconds"] if c == "malvar" else r["gains"][c]["seconds"]
                                          for r in rows]))
    if pick is None:
        best = max(worst.values())
        pick = max((c for c in worst if worst[c] >= best - tie_db), key=lambda c: (median[c], worst[c]))
    ratios = [r["lens_ratio"] for r in rows if r.get("lens_ratio") is not None]
    return {"sigma_from": lo, "sigma_to": hi, "candidate": pick, "view": view, "captures": len(rows),
            "worst_gain_db": worst[pick], "median_gain_db": median[pick], "tie_db": tie_db,
            "worst_gains_db": worst, "median_gains_db": median, "median_seconds": seconds,
            "lens_ratio_range": [min(ratios), max(ratios)] if ratios else None}


def is_costly(candidate: str) -> bool:
    return candidate != "malvar" and parse_candidate(candidate)[0] in COSTLY_METHODS


def _cheap_band(rows: list[dict], lo: float, hi: float, view: str, tie_db: float) -> dict:
    """:func:`_band` among the cheap candidates only (every candidate but :data:`COSTLY_METHODS`)."""
    return _band(without_costly(rows), lo, hi, view, tie_db)


def _costly_case(rows: list[dict], lo: float, hi: float, view: str, tie_db: float) -> dict | None:
    """The best costly candidate of the band (its worst case, then its median) and its worst-case gain over
    the cheap pick's: None where the rows hold no costly candidate."""
    band = _band(rows, lo, hi, view, tie_db)
    costly = [c for c in band["worst_gains_db"] if is_costly(c)]
    if not costly:
        return None
    best = max(costly, key=lambda c: (band["worst_gains_db"][c], band["median_gains_db"][c]))
    cheap = _cheap_band(rows, lo, hi, view, tie_db)
    return {"candidate": best, "over_cheap_db": band["worst_gains_db"][best] - cheap["worst_gain_db"]}


def _pick(rows: list[dict], lo: float, hi: float, view: str, tie_db: float, margin_db: float,
          pick: str | None = None) -> dict:
    """The band of :func:`fit_rule` over ``rows``: ``pick``, or else the cheap pick; with the cheap pick and
    the margin recorded where the rows hold a costly candidate."""
    cheap = _cheap_band(rows, lo, hi, view, tie_db)
    band = _band(rows, lo, hi, view, tie_db, pick or cheap["candidate"])
    if any(is_costly(c) for c in band["worst_gains_db"]):
        band["cheap_pick"] = {"candidate": cheap["candidate"], "worst_gain_db": cheap["worst_gain_db"],
                              "median_gain_db": cheap["median_gain_db"]}
        band["costly_margin_db"] = margin_db
    return band


def costly_picks(cases: list[dict | None], margin_db: float) -> list[str | None]:
    """Per band, darkest first (:func:`_costly_case`'s), the costly candidate that takes it, or None.

    A costly candidate takes the bands where its worst-case gain beats the cheap pick's by ``margin_db``, and
    every darker band where it is at least the cheap pick's: its gain comes from averaging along the epipolar
    lines, which pays more the darker the raw, so a darker band's worst case a few hundredths short of the
    margin is one capture's spread, not a reason to give the band back (docs/auto.md, "admm-epi at low light").
    """
    picks: list[str | None] = [None] * len(cases)
    paying = None
    for k in reversed(range(len(cases))):
        case = cases[k]
        if case is None:
            continue
        if case["over_cheap_db"] >= margin_db:
            paying = case["candidate"]
        if paying is not None and case["over_cheap_db"] >= 0.0:
            picks[k] = case["candidate"]
    return picks


def fit_rule(rows: list[dict], view: str, tie_db: float = TIE_DB, margin_db: float = COSTLY_MARGIN_DB
             ) -> list[dict]:
    """The sigma bands of ``rows`` (research/fit_auto.py) with, in each, the candidate of the best worst-case
    gain over Malvar on ``view``; among those within ``tie_db`` of it, the one of the largest median
    :func:`row_merit` (the gain; for ``both`` the mean of the two views' gains). Costly candidates
    (:data:`COSTLY_METHODS`) are left out of that choice, and take the band instead where their worst-case
    gain is at least ``margin_db`` above the cheap pick's, and in the darker bands where it is at least the
    cheap pick's (:func:`costly_picks`).

    Malvar is a candidate (gain 0), so no band's pick is more than ``tie_db`` worse than Malvar on any
    of its training captures. Neighbouring bands with the same pick are merged.
    """
    edges = _band_edges(rows)
    spans = [(lo, hi, [r for r in rows if lo <= r["sigma"] < hi]) for lo, hi in itertools.pairwise(edges)]
    spans = [span for span in spans if span[2]]
    costly = costly_picks([_costly_case(inside, lo, hi, view, tie_db) for lo, hi, inside in spans], margin_db)
    bands = []
    for (lo, hi, inside), pick in zip(spans, costly):
        band = _pick(inside, lo, hi, view, tie_db, margin_db, pick)
        if bands and bands[-1]["candidate"] == band["candidate"]:
            lo = bands.pop()["sigma_from"]
            band = _pick([r for r in rows if lo <= r["sigma"] < hi], lo, hi, view, tie_db, margin_db,
                         band["candidate"])
        bands.append(band)
    return bands


def without_costly(rows: list[dict]) -> list[dict]:
    """``rows`` with the gains of :data:`COSTLY_METHODS` left out."""
    return [{**r, "gains": {c: g for c, g in r["gains"].items() if not is_costly(c)}} for r in rows]


def fit_rules(rows: list[dict], tie_db: float = TIE_DB, margin_db: float = COSTLY_MARGIN_DB) -> dict:
    """The rule file's contents from research/fit_auto.py's rows: a rule per view, over every training capture;
    and a rule per view fitted without the costly methods (``cheap_rules``: ``--auto-cheap``).

    One rule for all content: a class of its own for content like the real light fields (cross-lens ratio
    below 2.6: of the training captures only finetexture, two a level) picked admm-uv-xc at strength 2 in
    one band, 1.9 dB below Malvar on the held-out Lytro frame at 12 lux (docs/auto.md), so it went.
    """
    rules = {view: fit_rule(rows, view, tie_db, margin_db) for view in VIEWS}
    cheap = {view: fit_rule(without_costly(rows), view, tie_db, margin_db) for view in VIEWS}
    return {"criterion": "per sigma band, the candidate of the best worst-case PSNR gain over Malvar on the "
                         f"training captures (lower of centre view and mean image for 'both'); within {tie_db:g} "
                         f"dB of it, the largest median gain; a costly method ({', '.join(COSTLY_METHODS)}) only "
                         f"where its worst-case gain beats the cheap pick's by {margin_db:g} dB, and in the "
                         "darker bands where it is no worse than the cheap pick's",
            "captures": sorted({r["capture"] for r in rows}),
            "rules": rules, "cheap_rules": cheap}


def parse_candidate(name: str) -> tuple[str, float, str | None]:
    """'method[@strength][:start]' -> (method, strength, start): the method and its start are
    lfcl.demosaic.names.parse_method_spec's ``METHOD[:START]`` (checked there), ``@strength`` multiplies the
    default lambda.

    'admm-uv@2' -> ('admm-uv', 2.0, 'malvar'); 'admm-uv-xc@1:linear4d' -> ('admm-uv-xc', 1.0, 'linear4d');
    'malvar' -> ('malvar', 1.0, 'malvar'); 'admm-epi@1' -> ('admm-epi', 1.0, None): without a start, the
    methods of :data:`OWN_START_METHODS` take their own.
    """
    head, colon, start = name.partition(":")
    method, at, strength = head.partition("@")
    method, start = parse_method_spec(method + colon + start)
    try:
        value = float(strength) if at else 1.0
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"candidate {name!r}: the strength after @ must be a number > 0, got {strength!r}")
    return method, value, start or (None if method in OWN_START_METHODS else "malvar")


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
    entry of ``parameters["auto"]`` (lfcl/demosaic/auto_report.py lists it)."""
    method = choice.method if method is None else method
    strength = choice.strength if strength is None else strength
    at = f" at strength {strength:g}" if strength != 1 else ""
    ran = dataclasses.replace(choice, method=method, strength=strength, start="malvar",
                              reason=f"{choice.reason}; {why}, so {method}{at} from a Malvar start")
    return ran, {"method": choice.method, "strength": choice.strength, "start": choice.start, "why": why}


def for_pitch(choice: AutoChoice, pitch) -> tuple[AutoChoice, dict | None]:
    """``choice`` and None if it runs on lenses of ``pitch``, else :func:`replacement`'s pair:
    linear4d (as the method or the start, the guarded start included) has coefficients for one pitch only."""
    if "linear4d" not in (choice.method, choice.start) and choice.start != "guarded":
        return choice, None
    from ..ops.linear4d import load_model

    fitted, pitch = tuple(load_model().pitch), tuple(int(p) for p in pitch)
    if pitch == fitted:
        return choice, None
    why = f"linear4d has coefficients for {fitted[0]}x{fitted[1]} lenses only, not {pitch[0]}x{pitch[1]}"
    return replacement(choice, why, *((AUTO_FALLBACK, 1.0) if choice.method == "linear4d" else ()))


def min_lenses(pitch) -> int:
    """The fewest lenses on a side of a frame on which ``auto`` runs a prior: twice the halo of admm-epi's bands
    (lfcl.solvers.epi.epi_halo at :func:`prior_dmax`: how far its lines and their interpolation reach; 12 lenses at
    pitch 9). On a narrower frame most lenses lie that close to its edge, where the lines leave the frame; there the
    default lost to Malvar (4-12 lenses a side at pitch 9: down to -10 dB at 4, -0.76 at 10, -0.23 at 12; the cheaper
    methods too, admm-uv-xc down to -1.6 dB at 4 and -2.9 at 12 with the noise estimated from the raw), and not at 24
    (docs/auto.md, "Small frames"), so ``auto`` runs Malvar there."""
    from ..solvers.epi import epi_halo

    return 2 * epi_halo([prior_dmax()], pitch)


def prior_dmax() -> float:
    """The widest disparity admm-epi searches (lenses per view step; lfcl.depth.estimate's default unless
    lfcl.solvers.epi.EPI_DEPTH_OPTIONS says otherwise): with the pitch it sets how far the prior's lines reach."""
    from ..depth.estimate import DEFAULTS
    from ..solvers.epi import EPI_DEPTH_OPTIONS

    return float({**DEFAULTS, **EPI_DEPTH_OPTIONS}["dmax"])


def small_frame(lenses, pitch) -> AutoChoice | None:
    """Malvar, and why, for a frame of ``lenses`` ``(S, T)`` narrower than :func:`min_lenses` on a side; else None."""
    S, T = (int(n) for n in lenses)
    fewest = min_lenses(pitch)
    if min(S, T) >= fewest:
        return None
    reason = (f"a frame of {S}x{T} lenses, fewer than {fewest} on a side: the priors' lines reach "
              f"{fewest // 2} lenses, so most lenses would lie at the frame's edge, where they lose to Malvar "
              "(docs/auto.md, \"Small frames\")")
    return AutoChoice("malvar", 1.0, None, reason, None)


def on_resampled_grid(kind: str) -> AutoChoice:
    """Malvar, and why, on a resampled lens grid (``kind``: rotated, non-integer pitch, hexagonal).

    There each prior the resampled solver has (admm-uv, admm-uvst, admm-st; no net, no cross-channel term, no
    admm-epi) fell below Malvar - 0.1 dB on 10-17 of 20 training captures at each of 0.5, 2, 12 and 50 lux (hex and
    rotated grids, charts, deadleaves, finetexture, periodic and gratings at seeds 1 and 2), worst -0.4 to -1.5 dB,
    median gains within +-0.6 dB (docs/auto.md, "Resampled grids"): no band where one is never worse."""
    reason = (f"a {kind} lens grid: every prior of the resampled solver (admm-uv, admm-uvst, admm-st) lost to Malvar on "
              "most training captures at every light level there (docs/auto.md, \"Resampled grids\")")
    return AutoChoice("malvar", 1.0, None, reason, None)


def choose(sigma: float, rule=None, lens_ratio: float | None = None, view: str = "both",
           rules: dict | None = None, costly: bool = True) -> AutoChoice:
    """The method and strength for noise level ``sigma``: from the sigma bands ``rule`` if given, else
    from the rule file's contents ``rules`` (default: the shipped file), its rule for ``view``
    (``VIEWS``: what its gains were judged on); ``costly`` False: its rule fitted without
    :data:`COSTLY_METHODS` (``--auto-cheap``: the methods of about admm-uv's time).

    ``lens_ratio``: the raw's cross-lens ratio (lfcl/demosaic/lens_ratio.py), recorded; when it lies outside what
    the band's training captures spanned, the reason says that the rule has not seen such content.
    """
    if not (isinstance(sigma, (int, float)) and math.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"auto needs a finite noise level >= 0, got {sigma!r}")
    check_view(view)
    cheap_rule = None  # the rule without the costly methods, to name what --auto-cheap would run
    if rule is None:
        rules = load_rules() if rules is None else rules
        rule = rule_bands(rules, view, costly)
        cheap_rule = rule_bands(rules, view, False) if costly else None
        if not rule:
            which = "" if costly else " without the costly methods"
            raise ValueError(f"the auto rule holds no rule{which} for view {view!r}: refit it with "
                             "research/fit_auto.py")
    band, where = band_for(sigma, rule)
    method, strength, start = parse_candidate(band["candidate"])
    cheap = band.get("cheap_pick")
    if cheap is not None and is_costly(band["candidate"]):
        why = (f"{band['candidate']}'s worst-case PSNR gain over Malvar ({VIEW_WORDS[view]}) against the cheaper "
               f"methods' best, {cheap['candidate']}'s {cheap['worst_gain_db']:+.2f} dB (a costly method runs where "
               f"it beats that by {band['costly_margin_db']:g} dB, and in darker bands where it is no worse)")
    else:
        why = (f"{band['candidate']} had the best worst-case PSNR gain over Malvar ({VIEW_WORDS[view]}), within "
               f"{band['tie_db']:g} dB, and the largest median gain")
    reason = (("" if costly else f"without the costly methods ({', '.join(COSTLY_METHODS)}): ") +
              f"sigma {sigma:.3g} {where} {band['sigma_from']:.3g}-{band['sigma_to']:.3g}: on its "
              f"{band['captures']} training captures {why} ({band['worst_gain_db']:+.2f} dB worst, "
              f"{band['median_gain_db']:+.2f} dB median)")
    if cheap_rule and is_costly(band["candidate"]):
        reason += f"; --auto-cheap runs {band_for(sigma, cheap_rule)[0]['candidate']} here"
    seen = None
    trained = band.get("lens_ratio_range")
    if lens_ratio is not None and trained:
        seen = trained[0] <= lens_ratio <= trained[1]
        if not seen:
            reason += (f"; the raw's cross-lens ratio {lens_ratio:.2f} lies outside the {trained[0]:.2f}-"
                       f"{trained[1]:.2f} of those captures, so the rule has not seen such content")
    return AutoChoice(method, strength, float(sigma), reason, start, lens_ratio, seen, view, costly)
