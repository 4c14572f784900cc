"""simulate -> process -> evaluate through the CLI, and the method layer's defaults."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from lfcl.cli import cli
from lfcl.evaluation.metrics import centre_view, lightfield_scores
from lfcl.io.images import read_image


@pytest.fixture(scope="module")
def capture_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("cap") / "capture"
    result = CliRunner().invoke(cli, ["simulate", "--scene", "deadleaves", "--lenses", "12x14", "--lux", "4",
                                      "--seed", "3", "-o", str(out)])
    assert result.exit_code == 0, result.output
    return out


def test_process_writes_the_exchange_layout(capture_dir, tmp_path):
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["process", str(capture_dir / "raw.dng"), "--pitch", "9", "--method", "admm-uv",
                                      "-o", str(out), "--outputs", "lightfield,center", "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["method"] == "admm-uv" and summary["iterations"] >= 1
    lightfield = np.load(out / "lightfield.npy")
    truth = np.load(capture_dir / "truth.npy")
    assert lightfield.shape == truth.shape == (12, 14, 9, 9, 3) and lightfield.dtype == np.float32
    np.testing.assert_allclose(read_image(out / "center.exr"), centre_view(lightfield), atol=0)
    assert lightfield_scores(lightfield, truth)["psnr_center"] > 30
    # previews are on by default (center.png) and every run records summary.json (docs/outputs.md)
    assert sorted(p.name for p in out.iterdir()) == ["center.exr", "center.png", "lightfield.npy", "summary.json"]
    assert json.loads((out / "summary.json").read_text()) == summary


def test_admm_uv_improves_on_malvar_at_low_light(capture_dir, tmp_path):
    scores = {}
    for method in ("malvar", "admm-uv"):
        out = tmp_path / method
        result = CliRunner().invoke(cli, ["process", str(capture_dir / "raw.dng"), "--method", method,
                                          "-o", str(out), "--outputs", "lightfield"])
        assert result.exit_code == 0, result.output
        scores[method] = lightfield_scores(np.load(out / "lightfield.npy"), np.load(capture_dir / "truth.npy"))
    assert scores["admm-uv"]["psnr_center"] > scores["malvar"]["psnr_center"] + 0.5


def test_evaluate_writes_table_and_figures(capture_dir, tmp_path):
    out = tmp_path / "eval"
    result = CliRunner().invoke(cli, ["evaluate", str(capture_dir), "--methods", "malvar,admm-uv",
                                      "--gradients", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "| Center |" in result.output and "| Mean Image |" in result.output
    report = json.loads((out / "eval.json").read_text())
    assert [r["method"] for r in report["results"]] == ["malvar", "admm-uv"]
    assert set(report["gradients"]) == {"u", "v", "s", "t"}
    for name in ("eval.md", "error_center.png", "crops_center.png", "error_mean.png", "gradients.png"):
        assert (out / name).stat().st_size > 0
    # Colour-artefact metrics (docs/colour-metrics.md): keys per view in eval.json, rows in the table.
    for r in report["results"]:
        for view in ("center", "mean"):
            assert 0 < r[f"de2000_mean_{view}"] < r[f"de2000_p95_{view}"] < 100
            assert r[f"hf_chroma_error_{view}"] > 0
            # deadleaves has (almost) no grey pixels: false colour is undefined there, null in JSON
            assert f"false_colour_{view}" in r and (r[f"false_colour_{view}"] is None or r[f"false_colour_{view}"] > 0)
    for label in ("ΔE00 mean", "ΔE00 p95", "False colour", "HF chroma error"):
        for view in ("centre", "mean image"):
            assert f"| {label} ({view}) |" in result.output
    assert "| False colour (centre) |" in (out / "eval.md").read_text()


def test_evaluate_sweep_tabulates_and_plots_colour_errors(capture_dir, tmp_path):
    out = tmp_path / "eval"
    result = CliRunner().invoke(cli, ["evaluate", str(capture_dir), "--methods", "malvar", "--sweep-lux", "2,8",
                                      "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "Colour errors against illumination, centre" in result.output
    assert "Colour errors against illumination, mean image" in result.output
    sweep = json.loads((out / "eval.json").read_text())["sweep"]
    assert [e["lux"] for e in sweep] == [2, 8]
    assert all("de2000_mean_center" in e["results"][0] and "false_colour_mean" in e["results"][0] for e in sweep)
    for name in ("psnr_vs_lux.png", "de2000_vs_lux.png"):
        assert (out / name).stat().st_size > 0


def test_evaluate_rejects_a_truth_of_another_shape(capture_dir, tmp_path):
    bad = tmp_path / "bad"
    bad.mkdir()
    for name in ("raw.dng", "meta.json"):
        (bad / name).write_bytes((capture_dir / name).read_bytes())
    np.save(bad / "truth.npy", np.zeros((3, 3, 9, 9, 3), np.float32))
    result = CliRunner().invoke(cli, ["evaluate", str(bad), "--methods", "malvar"])
    assert result.exit_code == 1
    assert "truth.npy has shape" in result.output and len(result.output.strip().splitlines()) == 1
    assert not (bad / "eval").exists()


def test_evaluate_refuses_a_grid_capture_and_a_broken_meta_in_one_line(capture_dir, tmp_path):
    grid = tmp_path / "grid"
    result = CliRunner().invoke(cli, ["simulate", "--grid", "hex", "--pitch", "10.3", "--lenses", "12x12",
                                      "-o", str(grid)])
    assert result.exit_code == 0, result.output
    broken = tmp_path / "broken"
    broken.mkdir()
    for name in ("raw.dng", "truth.npy"):
        (broken / name).write_bytes((capture_dir / name).read_bytes())
    (broken / "meta.json").write_text("{not json")
    for folder, words in ((grid, "is a capture of a hex lens grid"), (broken, "meta.json is not valid JSON")):
        result = CliRunner().invoke(cli, ["evaluate", str(folder), "--methods", "malvar"])
        assert result.exit_code == 1 and words in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1 and not (folder / "eval").exists()


@pytest.mark.parametrize("args,message", [
    (["--methods", "malvar,bogus"], "unknown method"),
    (["--sweep-lux", "1,-2"], "positive"),
])
def test_evaluate_bad_options(capture_dir, tmp_path, args, message):
    result = CliRunner().invoke(cli, ["evaluate", str(capture_dir), "-o", str(tmp_path / "e"), *args])
    assert result.exit_code == 1 and message in result.output
    assert not (tmp_path / "e").exists()


def test_process_bad_inputs(tmp_path):
    junk = tmp_path / "junk.dng"
    junk.write_bytes(b"not a raw file at all" * 10)
    result = CliRunner().invoke(cli, ["process", str(junk), "-o", str(tmp_path / "out")])
    assert result.exit_code == 1 and len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
    result = CliRunner().invoke(cli, ["process", str(junk), "-o", str(tmp_path / "out"), "--outputs", "center,nope"])
    assert result.exit_code == 1 and "unknown outputs" in result.output


def test_the_progress_bar_takes_every_method_name():
    """`lfcl process`'s bar: its total for any name of METHODS (auto chooses during the run: no total)."""
    from types import SimpleNamespace

    from lfcl.cli.commands.process import IterationBar, iteration_total
    from lfcl.demosaic.methods import ADMM_DEFAULTS
    from lfcl.demosaic.names import METHODS

    for method in METHODS:
        cap = ADMM_DEFAULTS[method].max_iter if method in ADMM_DEFAULTS else None
        assert iteration_total(method) == cap
        assert iteration_total(method, tolerance_db=0.5) == (None if cap is None else max(cap, 60))
        assert iteration_total(method, iterations=7) == 7
        bar = IterationBar(method, None)
        for i in (1, 2, 1):  # the third starts a second band of lens rows
            bar(SimpleNamespace(iteration=i, rms_change=1e-3), None)
        assert bar.bar.total == cap and bar.band == 1
        bar.close()
    assert iteration_total("auto") is None
