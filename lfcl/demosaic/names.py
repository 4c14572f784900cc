"""The names of the demosaic/denoise methods, importable without numpy (for `lfcl --help`).

What each does and its defaults: lfcl/demosaic/methods.py.
"""

METHODS = ("auto", "malvar", "admm-uv", "admm-st", "admm-uvst", "linear4d", "admm-uv-xc", "admm-uvst-xc",
           "admm-epi")

#: What `lfcl process`, the Demosaic stage and the default recipe run when no method is named: auto (its rule
#: fitted never worse than Malvar on the training captures, the safety net after its pick) was within 0.01 dB
#: of Malvar or above on both views on every cell of `lfcl bench matrix`, held-out scenes and the two real
#: light fields, and gained the most on the centre view (docs/auto.md, "Never worse than Malvar").
DEFAULT_METHOD = "auto"

#: The ADMM methods' first estimates: the paper's Malvar, the learned 4D filter, Malvar bounded to each lens,
#: and the learned filter with Malvar in the lenses where the two disagree far more than elsewhere.
STARTS = ("malvar", "linear4d", "lens-malvar", "guarded")

#: The methods that compute their answer in one pass and so take no start.
ONE_PASS = ("malvar", "linear4d")

#: The methods that run on a resampled lens grid (rotated, non-integer pitch, hexagonal; lfcl/demosaic/resampled.py):
#: Malvar and the ADMM priors the resampled solver has (lfcl/solvers/resampled.py), from the Malvar start only.
RESAMPLED_METHODS = ("malvar", "admm-uv", "admm-st", "admm-uvst")

#: The methods whose prior couples no two lenses, so that flat lenses can leave the solve
#: (lfcl/demosaic/flat_lenses.py), and the chi-square p-value above which a lens counts as flat.
SKIPPABLE = ("admm-uv", "admm-uv-xc")
FLAT_P = 0.01


def parse_method_spec(text: str) -> tuple[str, str | None]:
    """``METHOD[:START]`` -> (method, start or None): the one spelling of a method and its ADMM start
    (`lfcl process --method`, recipes, the Demosaic stage, `lfcl evaluate --methods`, `lfcl bench pareto
    --methods`, the auto rule's candidates). A method not in :data:`METHODS` or a start not in :data:`STARTS`:
    a one-line ValueError naming the allowed values; so is a start on a one-pass method (:data:`ONE_PASS`).

    >>> parse_method_spec("admm-uv-xc:guarded"), parse_method_spec("malvar")
    (('admm-uv-xc', 'guarded'), ('malvar', None))
    """
    if not isinstance(text, str):
        raise ValueError(f"a method is a string METHOD[:START], got {text!r}")
    method, colon, start = text.partition(":")
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}: expected one of {', '.join(METHODS)} (METHOD[:START])")
    if colon and start not in STARTS:
        raise ValueError(f"unknown start {start!r} in method {text!r}: expected METHOD:START with START one of "
                         f"{', '.join(STARTS)}")
    if colon and method in ONE_PASS:
        raise ValueError(f"{method} takes no start ({text!r}): it computes its answer in one pass; a start is for "
                         f"the iterative methods")
    return method, start if colon else None


def method_spec(method: str, start: str | None = None) -> str:
    """(method, start or None) -> ``METHOD[:START]``, checked as :func:`parse_method_spec` checks it."""
    text = method if start is None else f"{method}:{start}"
    parse_method_spec(text)
    return text
