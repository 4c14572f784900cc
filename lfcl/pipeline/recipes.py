"""Stage recipes: TOML files of `lfcl process` settings (docs/stages.md).

A recipe is a flat TOML table; every key is optional and has a default (:data:`DEFAULTS`)::

    description = "..."           # free text
    method = "auto"               # any of lfcl.demosaic.names.METHODS
    strength = 1.0                # > 0, multiplies the default lambda
    lambda = 0.01                 # >= 0; absent: follows the noise level
    iterations = 20               # >= 1; absent: the method's early-stopping rule
    outputs = ["center", "mean", "lightfield"]   # or "center,mean,lightfield"
    refocus = "-1:1:0.25"         # slopes, used with the refocus output
    format = "exr"                # exr or tiff
    previews = true               # 8-bit sRGB PNGs beside the images

The packaged recipes (``default``, ``lowlight``, ``preview``) live in ``lfcl/pipeline/recipe_files/`` of the
source tree, shipped as the data package ``lfcl.pipeline.recipe_files``; :func:`load_recipe` takes one of those
names or a path to a ``.toml`` file.
"""

from __future__ import annotations

import importlib.resources
import tomllib
from pathlib import Path

from ..demosaic.names import DEFAULT_METHOD

DEFAULTS = {
    "description": "",
    "method": DEFAULT_METHOD,
    "strength": 1.0,
    "lambda": None,
    "iterations": None,
    "outputs": ["center", "mean", "lightfield"],
    "refocus": "-1:1:0.25",
    "format": "exr",
    "previews": True,
}
PACKAGED = ("default", "lowlight", "preview")


def recipe_dir():
    """The folder (a Traversable) that holds the packaged ``*.toml`` recipes.

    lfcl/pipeline/recipe_files/ in the source tree, installed as the data package ``lfcl.pipeline.recipe_files``.
    """
    return importlib.resources.files("lfcl.pipeline.recipe_files")


def _check(data: dict, where: str) -> dict:
    from ..demosaic.methods import METHODS
    from ..outputs.files import parse_format, parse_outputs
    from ..outputs.refocus import parse_slopes

    unknown = sorted(set(data) - set(DEFAULTS))
    if unknown:
        raise ValueError(f"{where}: unknown key {', '.join(map(repr, unknown))}; known: {', '.join(DEFAULTS)}")
    out = {**DEFAULTS, **data}

    def bad(key, why):
        return ValueError(f"{where}: {key} = {data[key]!r}: {why}")

    def number(x):
        return isinstance(x, (int, float)) and not isinstance(x, bool)

    if not isinstance(out["description"], str):
        raise bad("description", "must be a string")
    if out["method"] not in METHODS:
        raise bad("method", f"must be one of {', '.join(METHODS)}")
    if not number(out["strength"]) or not out["strength"] > 0:
        raise bad("strength", "must be a number > 0")
    out["strength"] = float(out["strength"])
    if out["lambda"] is not None:
        if not number(out["lambda"]) or not out["lambda"] >= 0:
            raise bad("lambda", "must be a number >= 0")
        out["lambda"] = float(out["lambda"])
    if out["iterations"] is not None and (not isinstance(out["iterations"], int) or isinstance(out["iterations"], bool)
                                          or out["iterations"] < 1):
        raise bad("iterations", "must be an integer >= 1")
    outputs = out["outputs"]
    if isinstance(outputs, list) and all(isinstance(o, str) for o in outputs):
        outputs = ",".join(outputs)
    if not isinstance(outputs, str):
        raise bad("outputs", "must be a list of output names or a comma-separated string")
    try:
        out["outputs"] = parse_outputs(outputs)
    except ValueError as e:
        raise bad("outputs", str(e)) from None
    if not isinstance(out["refocus"], str):
        raise bad("refocus", "must be a string like '-1:1:0.25' or '-0.5,0,0.5'")
    try:
        parse_slopes(out["refocus"])
    except ValueError as e:
        raise bad("refocus", str(e)) from None
    try:
        out["format"] = parse_format(out["format"]) if isinstance(out["format"], str) else None
    except ValueError:
        out["format"] = None
    if out["format"] is None:
        raise bad("format", "must be exr or tiff")
    if not isinstance(out["previews"], bool):
        raise bad("previews", "must be true or false")
    return out


def load_recipe(name_or_path) -> dict:
    """A packaged recipe by name (``default``, ``lowlight``, ``preview``) or a ``.toml`` file by path.

    Returns every key of :data:`DEFAULTS` (defaults filled in; ``lambda``/``iterations`` None
    when absent) plus ``name`` and ``path``. An unknown key, a bad value, unreadable TOML or a
    name that is neither a packaged recipe nor a file: one-line ``ValueError`` naming it.
    """
    text_name = str(name_or_path)
    path = Path(text_name)
    if isinstance(name_or_path, str) and "/" not in text_name and "\\" not in text_name \
            and not text_name.endswith(".toml"):
        folder = recipe_dir()
        resource = folder.joinpath(f"{text_name}.toml")
        if not resource.is_file():
            known = sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))
            raise ValueError(f"unknown recipe {text_name!r}: packaged recipes are {', '.join(known)} "
                             "(or give a path to a .toml file)")
        text, where, name = resource.read_text(encoding="utf-8"), f"recipe {text_name}", text_name
        path_text = str(resource)
    else:
        if not path.is_file():
            raise ValueError(f"recipe file {text_name!r} does not exist")
        text, where, name, path_text = path.read_text(encoding="utf-8"), f"recipe {text_name}", path.stem, str(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"{where}: not valid TOML: {e}") from None
    recipe = _check(data, where)
    recipe.update(name=name, path=path_text)
    return recipe


def pipeline_from_recipe(recipe, **overrides):
    """A :class:`lfcl.pipeline.stages.Pipeline` from a recipe (a dict from :func:`load_recipe`, a name or a path).

    ``overrides``: recipe keys (``lam`` may stand for ``lambda``, ``fmt`` for ``format``) and
    the stages' other options: ``pattern``, ``pitch``, ``calibration``, ``white``, ``device``.
    Recipe keys are validated like the file's; ``None`` leaves the recipe's value.
    """
    from ..demosaic.auto import view_for_outputs
    from .stages import Decode, Demosaic, Grid, Outputs, Pipeline

    if not isinstance(recipe, dict):
        recipe = load_recipe(recipe)
    aliases = {"lam": "lambda", "fmt": "format"}
    extra_keys = ("pattern", "pitch", "calibration", "white", "device")
    given = {aliases.get(k, k): v for k, v in overrides.items() if v is not None}
    unknown = sorted(k for k in given if k not in DEFAULTS and k not in extra_keys)
    if unknown:
        raise ValueError(f"pipeline_from_recipe: unknown option {', '.join(map(repr, unknown))}")
    where = f"recipe {recipe.get('name', '?')} with overrides"
    base = {k: recipe[k] for k in DEFAULTS if recipe.get(k) is not None}
    merged = _check({**base, **{k: v for k, v in given.items() if k in DEFAULTS}}, where)
    merged.update(name=recipe.get("name"), path=recipe.get("path"))
    pipeline = Pipeline([
        Decode(given.get("pattern")),
        Grid(pitch=given.get("pitch"), calibration=given.get("calibration"), white=given.get("white"),
             pattern=given.get("pattern")),
        Demosaic(merged["method"], lam=merged["lambda"], iterations=merged["iterations"],
                 strength=merged["strength"], device=given.get("device"),
                 auto_view=view_for_outputs(merged["outputs"])),  # as `lfcl process`: auto judged on the outputs
        Outputs(merged["outputs"], refocus=merged["refocus"], fmt=merged["format"], previews=merged["previews"]),
    ], recipe=merged)
    # every output file records the recipe and the options used (as `lfcl process --recipe` does)
    pipeline.stages[-1].metadata["recipe"] = {"name": merged["name"], "path": merged["path"],
                                              "options": pipeline.options()}
    return pipeline
