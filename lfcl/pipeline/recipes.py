"""Stage recipes: TOML files of `lfcl process` settings (docs/stages.md).

A recipe is a flat TOML table; every key is optional and has a default (:data:`DEFAULTS`). The keys, their
defaults and their checks are the stages' (lfcl/pipeline/parameters.py, the fields marked ``recipe``)::

    description = "..."           # free text
    method = "auto"               # METHOD[:START], as admm-uv-xc:guarded (lfcl.demosaic.names.parse_method_spec)
    strength = 1.0                # > 0, multiplies the default lambda
    lambda = 0.01                 # >= 0; absent: follows the noise level
    iterations = 20               # >= 1; absent: the method's early-stopping rule
    auto_costly = true            # with auto; false: its rule without the costly methods (--auto-cheap)
    outputs = ["center", "mean", "lightfield"]   # or "center,mean,lightfield"
    refocus = "-1:1:0.25"         # slopes, used with the refocus output
    format = "exr"                # exr, tiff or dng
    previews = true               # 8-bit sRGB PNGs beside the images

The packaged recipes (``default``, ``lowlight``, ``preview``) live in ``lfcl/pipeline/recipe_files/`` of the
source tree, shipped as the data package ``lfcl.pipeline.recipe_files``; :func:`load_recipe` takes one of those
names or a path to a ``.toml`` file.
"""

from __future__ import annotations

import importlib.resources
import tomllib
from pathlib import Path

from .parameters import STAGES, ParameterError, entries, recipe_defaults, recipe_entries, recipe_values

#: Every recipe key and its default: ``description`` (free text) and the stages' recipe keys
#: (lfcl/pipeline/parameters.py: the fields with ``recipe``), in the order recipes record them.
DEFAULTS = {"description": "", **recipe_defaults()}
PACKAGED = ("default", "lowlight", "preview")


def recipe_dir():
    """The folder (a Traversable) that holds the packaged ``*.toml`` recipes.

    lfcl/pipeline/recipe_files/ in the source tree, installed as the data package ``lfcl.pipeline.recipe_files``.
    """
    return importlib.resources.files("lfcl.pipeline.recipe_files")


def _check(data: dict, where: str) -> dict:
    """``data`` (recipe key -> value) with the defaults filled in, checked by the stages' schemas and normalised."""
    unknown = sorted(set(data) - set(DEFAULTS))
    if unknown:
        raise ValueError(f"{where}: unknown key {', '.join(map(repr, unknown))}; known: {', '.join(DEFAULTS)}")
    out = {**DEFAULTS, **data}
    if not isinstance(out["description"], str):
        raise ValueError(f"{where}: description = {out['description']!r}: must be a string")
    try:
        return {"description": out["description"], **recipe_values(out)}
    except ParameterError as e:
        raise ValueError(f"{where}: {e.key} = {out[e.key]!r}: {e.why}") from None


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
        if path.is_dir():
            raise ValueError(f"recipe {text_name!r} is a folder, not a .toml file")
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

    ``overrides``: recipe keys (a field's name may stand for its key: ``lam`` for ``lambda``, ``fmt`` for
    ``format``), any other option of the stages (lfcl/pipeline/parameters.py: ``pattern``, ``pitch``,
    ``calibration``, ``white``, ``tolerance_db``, ``skip_flat``, ...) and ``device``. Recipe keys are
    validated like the file's, the others by their stage; ``None`` leaves the recipe's value (or the default).
    """
    from ..demosaic.auto import view_for_outputs
    from .stages import Decode, Demosaic, Grid, Outputs, Pipeline

    if not isinstance(recipe, dict):
        recipe = load_recipe(recipe)
    else:  # checked as a file's keys are (a misspelt key would otherwise leave its default in silence)
        named = {k: recipe[k] for k in ("name", "path") if k in recipe}
        recipe = {**_check({k: v for k, v in recipe.items() if k not in ("name", "path")},
                           f"recipe {named.get('name', 'given as a dict')}"), **named}
    fields = {e.name: e for e in entries()}
    recipe_key = {e.name: e.key for e in recipe_entries()}
    both = sorted(name for name, key in recipe_key.items()
                  if name != key and overrides.get(name) is not None and overrides.get(key) is not None)
    if both:  # lam and lambda, fmt and format: one value each
        raise ValueError(f"pipeline_from_recipe: give {', '.join(f'{n!r} or {recipe_key[n]!r}' for n in both)}, "
                         "not both")
    given = {recipe_key.get(k, k): v for k, v in overrides.items() if v is not None}
    unknown = sorted(k for k in given if k not in DEFAULTS and k not in fields and k != "device")
    if unknown:
        raise ValueError(f"pipeline_from_recipe: unknown option {', '.join(map(repr, unknown))}")
    where = f"recipe {recipe.get('name', '?')} with overrides"
    base = {k: recipe[k] for k in DEFAULTS if recipe.get(k) is not None}
    merged = _check({**base, **{k: v for k, v in given.items() if k in DEFAULTS}}, where)
    merged.update(name=recipe.get("name"), path=recipe.get("path"))
    values = {**{k: v for k, v in given.items() if k in fields}, **{e.name: merged[e.key] for e in recipe_entries()}}
    values.setdefault("auto_view", view_for_outputs(merged["outputs"]))  # as `lfcl process`: auto judged on the outputs

    decode, grid, demosaic, outputs = (
        {e.name: values[e.name] for e in entries(schema) if e.name in values} for schema in STAGES)
    pipeline = Pipeline([
        Decode(**decode),
        Grid(**grid, pattern=values.get("pattern")),
        Demosaic(**demosaic, device=given.get("device")),
        Outputs(**outputs),
    ], recipe=merged)
    # every output file records the recipe and the options used (as `lfcl process --recipe` does)
    pipeline.stages[-1].metadata["recipe"] = {"name": merged["name"], "path": merged["path"],
                                              "options": pipeline.options()}
    return pipeline
