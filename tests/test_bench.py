"""`lfcl bench kernels|pareto|admm` through the CLI: the structure of their JSON, never their speed."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import pytest
from click.testing import CliRunner

from lfcl.cli import cli

KERNELS = [
    "copy (reference)", "CFA A", "CFA A^T", "CFA A^T A", "Malvar", "Malvar, lens-bounded", "Malvar vs colour-demosaicing",
    "linear4d", "lens disagreement", "lens swap (half the lenses)", "lens copy (half the lenses)",
    "lens fill (half the lenses)",
    "D uv", "D^T uv", "D^T D uv", "normal_apply uv", "jacobi_apply uv", "build_rhs uv", "lens_solve uv",
    "D_epi, colour-mixed", "D_epi^T",
    "D uvst", "D^T uvst", "D^T D uvst", "normal_apply uvst", "jacobi_apply uvst", "build_rhs uvst",
    "depth cost, 5 apertures", "depth window sums",
    "dot", "norm2", "diff_norm2", "abs_sum", "soft_threshold", "zu_update", "axpby",
]
# The cost volume's twin (per lens, in float64) is too slow for a kernel table at full size; tests/test_depth.py
# compares them.
NO_NUMPY_COLUMN = {"depth cost, 5 apertures"}


def _invoke(args):
    return CliRunner().invoke(cli, args)


def test_bench_kernels_json():
    result = _invoke(["bench", "kernels", "--size", "90x90", "--repeats", "2", "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["device"] and report["size"] == [90, 90] and report["lenses"] == [10, 10]
    assert report["elements"] == {"N": 8100, "P": 24300}
    assert [k["name"] for k in report["kernels"]] == KERNELS
    copy = report["kernels"][0]
    assert copy["bytes"] == 2 * report["light_field_bytes"]
    assert report["copy_gb_per_s"] == pytest.approx(copy["gb_per_s"])
    for k in report["kernels"]:
        assert len(k["times"]) == 2 and all(t > 0 for t in k["times"]), k["name"]
        assert k["seconds"] > 0 and k["bytes"] > 0 and k["traffic"] and k["kernel"]
        assert k["gb_per_s"] == pytest.approx(k["bytes"] / k["seconds"] / 1e9, rel=1e-9), k["name"]
        assert k["copy_fraction"] == pytest.approx(k["gb_per_s"] / copy["gb_per_s"], rel=1e-9)
        if k["name"] in NO_NUMPY_COLUMN:
            assert k["numpy_seconds"] is None and k["speedup"] is None
        else:
            assert k["numpy_seconds"] > 0 and k["speedup"] == pytest.approx(k["numpy_seconds"] / k["seconds"])
    # the documented minimum traffic, 4 bytes per float
    by_name = {k["name"]: k for k in report["kernels"]}
    N, P = 8100, 24300
    assert by_name["CFA A"]["bytes"] == 4 * 2 * N
    assert by_name["linear4d"]["bytes"] == 4 * 4 * N
    assert by_name["D uvst"]["bytes"] == 4 * 5 * P
    L = 100  # lenses; 21 candidates
    assert by_name["depth cost, 5 apertures"]["bytes"] == 4 * (N + 210 * L)
    assert by_name["depth window sums"]["bytes"] == 4 * (4 * 21 + 81) * L
    assert by_name["zu_update"]["bytes"] == 4 * 6 * P
    assert by_name["norm2"]["bytes"] == 4 * P
    assert by_name["lens disagreement"]["bytes"] == 4 * (2 * P + N)
    assert by_name["lens fill (half the lenses)"]["bytes"] == 4 * P // 2
    assert by_name["D_epi^T"]["bytes"] == 4 * 3 * P


def test_bench_kernels_table_and_errors():
    result = _invoke(["bench", "kernels", "--size", "18x18", "--repeats", "1", "--numpy-repeats", "0", "--only", "axpby"])
    assert result.exit_code == 0, result.output
    assert "axpby" in result.stdout and "copy (reference)" in result.stdout and "zu_update" not in result.stdout
    result = _invoke(["bench", "kernels", "--size", "90x91"])
    assert result.exit_code == 1 and "9x9 microlenses" in result.stderr
    result = _invoke(["bench", "kernels", "--size", "big"])
    assert result.exit_code == 1 and "--size" in result.stderr


def test_kernels_memory_check_names_the_limit(runtime):
    from lfcl.bench import kernels

    cases = kernels.build_cases(runtime, 4500, 4500, (9, 9))
    specs = kernels.buffer_specs(4500, 4500, (9, 9))
    small = SimpleNamespace(device=SimpleNamespace(name="tiny", max_mem_alloc_size=2**28, global_mem_size=2**40))
    with pytest.raises(ValueError, match="allocates at most 256 MiB"):
        kernels._check_memory(small, specs, cases, (4500, 4500))
    small.device.max_mem_alloc_size, small.device.global_mem_size = 2**40, 2**30
    with pytest.raises(ValueError, match="MiB of device memory at once"):
        kernels._check_memory(small, specs, cases, (4500, 4500))


def test_bench_pareto_json(tmp_path):
    out = tmp_path / "pareto"
    # every lens solved by default, as the reference does; without the safety net, which the reference has not
    result = _invoke(["bench", "pareto", "--lenses", "8x8", "--budgets", "1,2", "--no-safety-net", "--json", "-o",
                      str(out)])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["lenses"] == [8, 8] and report["budgets"] == [1, 2] and report["reference_budgets"] == [1, 2]
    assert report["skip_flat"] is None and report["safety_net"] is False
    points = report["points"]
    methods = [(p["method"], p["iterations"]) for p in points]
    assert methods == [("malvar", 0), ("linear4d", 0), ("admm-uv", 1), ("admm-uv", 2), ("admm-st", 1), ("admm-st", 2),
                       ("admm-uvst", 1), ("admm-uvst", 2), ("colour-demosaicing Malvar2004", 0),
                       ("numpy reference admm-uv (CG)", 1), ("numpy reference admm-uv (CG)", 2)]
    for p in points:
        assert p["seconds"] > 0 and math.isfinite(p["psnr_center"]) and math.isfinite(p["psnr_mean"]), p
        assert isinstance(p["front"], bool)
    assert any(p["front"] for p in points)
    # from the Malvar start the first x-update changes nothing, whatever solves it
    dev = {p["iterations"]: p for p in points if p["method"] == "admm-uv"}
    ref = {p["iterations"]: p for p in points if p["method"] == "numpy reference admm-uv (CG)"}
    assert dev[1]["psnr_center"] == pytest.approx(ref[1]["psnr_center"], abs=0.01)
    assert (out / "pareto.png").stat().st_size > 0
    assert json.loads((out / "pareto.json").read_text())["points"] == points
    assert "admm-uvst" in (out / "pareto.md").read_text()
    assert sorted(p.name for p in out.iterdir()) == ["pareto.json", "pareto.md", "pareto.png"]


def test_bench_pareto_without_colour_demosaicing(monkeypatch, tmp_path):
    import sys

    monkeypatch.setitem(sys.modules, "colour_demosaicing", None)  # import raises ImportError
    result = _invoke(["bench", "pareto", "--lenses", "8x8", "--budgets", "1", "-o", str(tmp_path / "p")])
    assert result.exit_code == 1
    assert "pip install 'lfcl[test]'" in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "p").exists()


def test_bench_admm_json():
    result = _invoke(["bench", "admm", "--lenses", "8x8", "--iterations", "2", "--repeats", "1",
                      "--methods", "admm-uv", "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    (row,) = report["methods"]
    assert row["method"] == "admm-uv" and row["device_iterations"] == 2 and row["reference_iterations"] == 2
    # CG like the reference, whatever the solver's default. The first x-update starts at the
    # Malvar solution, whose residual is zero in exact arithmetic: 0 steps or all 4.
    assert row["device_cg_steps"][0] in (0, 4) and row["device_cg_steps"][1:] == [4]
    # times, not asserted (an 8x8 solve on a busy machine can time T(2) <= T(1), a per-iteration time of 0)
    assert row["default_per_iteration"] >= 0 and row["default_x_update"]
    assert row["device_per_iteration"] >= 0 and row["reference_per_iteration"] >= 0
    assert row["speedup"] is None or row["speedup"] >= 0
    assert row["max_abs_diff"] < 1e-3


def test_admm_iteration_times_that_come_out_zero_give_no_ratio():
    from lfcl.bench.pareto import _ratio, per_iteration

    assert per_iteration(1.0, 2.0, 2) == 0.0  # T(k) below T(1): timer noise, clamped
    assert per_iteration(3.0, 1.0, 3) == 1.0 and per_iteration(3.0, 1.0, 1) == 3.0
    assert _ratio(2.0, 0.0) is None and _ratio(2.0, 0.5) == 4.0


def test_bench_pareto_takes_an_admm_method_with_its_start(tmp_path):
    result = _invoke(["bench", "pareto", "--lenses", "8x8", "--budgets", "2", "--reference-budgets", "none",
                      "--methods", "admm-uv,admm-uv:linear4d", "--json", "-o", str(tmp_path / "p")])
    assert result.exit_code == 0, result.output
    points = {p["method"]: p for p in json.loads(result.stdout)["points"]}
    assert points["admm-uv:linear4d"]["psnr_center"] != points["admm-uv"]["psnr_center"]
    bad = _invoke(["bench", "pareto", "--lenses", "8x8", "--budgets", "1", "--methods", "admm-uv:nearest",
                   "-o", str(tmp_path / "q")])
    assert bad.exit_code != 0 and "unknown ADMM method(s) admm-uv:nearest" in bad.output
    assert "optionally METHOD:START with START one of malvar, linear4d, lens-malvar, guarded" in bad.output
    bad = _invoke(["bench", "pareto", "--lenses", "8x8", "--budgets", "1", "--methods", "malvar:linear4d",
                   "-o", str(tmp_path / "r")])  # a spelling parse_method_spec takes, but no ADMM method
    assert bad.exit_code != 0 and "unknown ADMM method(s) malvar:linear4d" in bad.output


def test_bench_matrix_rows_and_the_worst_cell_first(tmp_path):
    result = _invoke(["bench", "matrix", "--scenes", "charts,finetexture", "--lux", "12", "--methods",
                      "admm-uvst,admm-uv", "--lenses", "8", "--shared", str(tmp_path / "none"), "--json"])
    assert result.exit_code == 0, result.output
    rows = json.loads(result.stdout)
    assert [(r["capture"], r["noise"], r["method"]) for r in rows] == [
        (scene, noise, method) for scene in ("charts", "finetexture") for noise in ("profile", "raw")
        for method in ("admm-uvst", "admm-uv")]
    for row in rows:
        assert row["lux"] == 12 and row["net"] is not None  # the safety net ran and said on how many lenses
    import dataclasses

    from lfcl.evaluation.evaluate import run_method, simulated_capture

    capture = simulated_capture(8, 12, seed=7, scene="charts")  # the matrix's held-out seed
    malvar = run_method(capture, "malvar")
    for row, source in zip(rows[:4:2], (capture, dataclasses.replace(capture, noise_profile=None))):
        uvst = run_method(source, "admm-uvst")  # with the DNG's noise profile, then without it
        assert row["centre_gain"] == pytest.approx(uvst["psnr_center"] - malvar["psnr_center"], abs=1e-9)
        assert row["mean_gain"] == pytest.approx(uvst["psnr_mean"] - malvar["psnr_mean"], abs=1e-9)
    assert rows[0]["centre_gain"] != rows[2]["centre_gain"]  # the two noise models differ
    from lfcl.bench.matrix import format_rows, worst

    table = format_rows(rows).splitlines()
    first = min(rows, key=worst)
    assert table[2].startswith(f"| {first['capture']} | 12 | {first['noise']} | {first['method']} |")
    assert table[-2].startswith(f"worst cell: {first['capture']} at 12 lux, noise from the {first['noise']}")
    below = sum(worst(r) < -0.1 for r in rows)
    assert table[-1].startswith(f"cells below Malvar - 0.1 dB: {below} of {len(rows)}; of them ")
    from lfcl.evaluation.evaluate import truth_noise

    assert [r["truth_noise"] for r in rows[:4]] == [truth_noise(capture)] * 4  # one figure per capture and level
    bad = _invoke(["bench", "matrix", "--scenes", "charts", "--lux", "12", "--lenses", "8", "--noise", "guess"])
    assert bad.exit_code != 0 and "noise sources must be among profile, raw" in bad.output


def test_bench_matrix_levels_sample_both_kinds_of_auto_band_below_the_brightest():
    """The default levels reach auto's cheaper band (a method outside COSTLY_METHODS) at more than its brightest level:
    the periodic scene was below Malvar inside that band, not at 50 lux, before admm-uv-xc was refitted (docs/auto.md)."""
    from lfcl.bench.matrix import HELD_OUT_SEED, LUX
    from lfcl.demosaic import auto
    from lfcl.evaluation.evaluate import simulated_capture
    from lfcl.noise.model import from_noise_profile

    result = _invoke(["bench", "matrix", "--help"])
    assert result.exit_code == 0 and "[default: " + ",".join(f"{v:g}" for v in LUX) + "]" in result.output
    costly = []
    for lux in LUX:
        capture = simulated_capture(24, lux, seed=HELD_OUT_SEED, scene="charts")
        sigma = from_noise_profile(capture.noise_profile, capture.mosaic).sigma
        costly.append(auto.choose(sigma).method in auto.COSTLY_METHODS)
    assert costly[0] and not costly[-1]
    assert sum(not c for c in costly) >= 2, dict(zip(LUX, costly))


def test_bench_matrix_finds_the_real_light_fields_it_is_given(tmp_path):
    from lfcl.bench.matrix import real_lightfields

    (tmp_path / "realdata" / "hci_epinet" / "antinous").mkdir(parents=True)
    assert real_lightfields(tmp_path) == {"antinous": str(tmp_path / "realdata" / "hci_epinet" / "antinous")}
    assert real_lightfields(tmp_path / "none") == {}


def test_bench_api_times_the_public_call_against_its_peer():
    result = _invoke(["bench", "api", "--size", "63x90", "--repeats", "2", "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["size"] == [63, 90] and report["repeats"] == 2
    assert report["lfcl_malvar_seconds"] > 0 and report["colour_demosaicing_seconds"] > 0
    assert report["speedup"] == pytest.approx(report["colour_demosaicing_seconds"] / report["lfcl_malvar_seconds"])
    assert report["lightfield_speedup"] == pytest.approx(
        report["colour_demosaicing_lightfield_seconds"] / report["lfcl_lightfield_seconds"])
    bad = _invoke(["bench", "api", "--size", "64x96", "--repeats", "1"])
    assert bad.exit_code != 0 and "whole 9x9 lenses" in bad.output


def test_bench_process_times_lfcl_process_per_method_against_its_peer(tmp_path):
    """Each method through `lfcl process` in its own process; its centre view scored against the truth as an
    independent path scores the same method (lfcl.lightfield), the ratios against the peer of the same run."""
    import numpy as np

    import lfcl
    from lfcl.evaluation.metrics import psnr
    from lfcl.sim import simulate, write_capture

    capture = write_capture(simulate("charts", lenses=(12, 14), lux=2.0, seed=3), tmp_path / "capture")
    result = _invoke(["bench", "process", str(capture), "--methods", "malvar,admm-epi", "--peer", "admm-uv",
                      "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    rows = {r["method"]: r for r in report["rows"]}
    assert [r["method"] for r in report["rows"]] == ["admm-uv", "malvar", "admm-epi"] and report["peer"] == "admm-uv"
    # admm-epi's disparity is reported apart by lfcl process; the demosaic stage counts it
    assert 0 < rows["admm-epi"]["disparity_seconds"] < rows["admm-epi"]["demosaic_seconds"]
    assert rows["malvar"]["disparity_seconds"] == rows["admm-uv"]["disparity_seconds"] == 0
    for row in rows.values():
        assert row["wall_seconds"] > row["demosaic_seconds"] > 0 and 0.01 < row["peak_rss_gb"] < 64
        assert row["wall_ratio"] == pytest.approx(row["wall_seconds"] / rows["admm-uv"]["wall_seconds"])
        assert row["demosaic_ratio"] == pytest.approx(row["demosaic_seconds"] / rows["admm-uv"]["demosaic_seconds"])
    truth = np.load(capture / "truth.npy")
    field = lfcl.lightfield(str(capture / "raw.dng"), pitch=9, method="malvar")
    assert rows["malvar"]["psnr_center"] == pytest.approx(psnr(field[:, :, 4, 4], truth[:, :, 4, 4]), abs=1e-3)
    assert rows["malvar"]["iterations"] == 0 and rows["admm-uv"]["iterations"] >= 1
    assert rows["admm-uv"]["mean_iterations"] == rows["admm-uv"]["iterations"]  # one solve, no bands
    bad = _invoke(["bench", "process", str(capture), "--methods", "admm-nope"])
    assert bad.exit_code == 1 and "unknown method" in bad.output
    empty = tmp_path / "empty"
    empty.mkdir()
    missing = _invoke(["bench", "process", str(empty)])
    assert missing.exit_code == 1 and "raw.dng is missing" in missing.output


def test_bench_process_averages_the_iterations_of_bands_over_their_lens_rows():
    """A banded solve stops band by band: its time follows the iterations averaged over the lens rows."""
    from lfcl.bench.process import _mean_iterations, format_report

    banded = {"iterations": 20, "parameters": {"bands": {"lens_rows": [10, 30], "iterations": [20, 8]}}}
    assert _mean_iterations(banded) == pytest.approx((10 * 20 + 30 * 8) / 40)
    assert _mean_iterations({"iterations": 7, "parameters": {}}) == 7.0
    assert _mean_iterations({"iterations": None}) is None
    row = {"method": "admm-epi", "wall_seconds": 2.0, "wall_ratio": 2.0, "demosaic_seconds": 1.0, "demosaic_ratio": 2.0,
           "disparity_seconds": 0.5, "peak_rss_gb": 1.0, "iterations": 20, "mean_iterations": 11.0, "psnr_center": None}
    table = format_report({"raw": "x", "outputs": "center", "repeats": 1, "peer": "admm-uv", "rows": [row]})
    assert "| 20 (11.0) |" in table
