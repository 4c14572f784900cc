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

#: The methods that run on a resampled lens grid (rotated, non-integer pitch, hexagonal; lfcl/demosaic/resampled.py):
#: Malvar and the ADMM priors the resampled solver has (lfcl/solvers/resampled.py), from the Malvar start only.
RESAMPLED_METHODS = ("malvar", "admm-uv", "admm-st", "admm-uvst")

#: The methods whose prior couples no two lenses, so that flat lenses can leave the solve
#: (lfcl/demosaic/flat_lenses.py), and the chi-square p-value above which a lens counts as flat.
SKIPPABLE = ("admm-uv", "admm-uv-xc")
FLAT_P = 0.01
