"""`preview` and `benchmark`: the viewport's draw path on the command line, with their file contracts."""

import json

import numpy as np
from conftest import run_cli


def test_preview_writes_each_frame_and_its_redraw_times(tmp_path):
    from nubis_addon.core.imageio import read_image

    out = tmp_path / "pv"
    r = run_cli(
        "preview",
        "--out",
        str(out),
        "--width",
        "64",
        "--height",
        "36",
        "--frames",
        "3-5",
        "--redraws",
        "2",
        "--orbit",
        "2",
        "--naive",
        "--quality",
        "draft",
    )
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stdout.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("previewed default at 64x36 (draft): 3 frame(s) x 2 redraw(s)")
    names = {p.name for p in out.iterdir()}
    expected = {f"{f:04d}{s}.{e}" for f in (3, 4, 5) for s in ("", "_naive") for e in ("exr", "png")}
    assert names == expected | {"preview.json"}
    report = json.loads((out / "preview.json").read_text())
    assert [f["frame"] for f in report["frames"]] == [3, 4, 5]
    assert all(len(f["redraw_ms"]) == 2 and min(f["redraw_ms"]) > 0 and f["naive_ms"] > 0 for f in report["frames"])
    assert report["quality"] == "draft" and report["orbit_degrees_per_frame"] == 2.0
    first = read_image(out / "0003.exr")
    assert first.shape == (36, 64, 4) and first[..., 3].max() > 0.3
    # The camera turns: the last frame is not the first one.
    assert np.abs(read_image(out / "0005_naive.exr") - read_image(out / "0003_naive.exr")).mean() > 1e-3


def test_preview_refuses_bad_ranges_before_any_work(tmp_path):
    for args, words in (
        (("--frames", "9-2"), "--frames 9-2"),
        (("--frames", "a-b"), "--frames takes"),
        (("--redraws", "0"), "--redraws"),
        (("--orbit", "nan"), "--orbit"),
    ):
        r = run_cli("preview", "--out", str(tmp_path / "x"), "--width", "16", "--height", "16", *args)
        assert r.returncode != 0
        assert r.stderr.startswith("nubis: error:") and words in r.stderr, r.stderr
        assert not list((tmp_path / "x").glob("*")) if (tmp_path / "x").exists() else True
    r = run_cli("preview", "--out", str(tmp_path / "y"), "--quality", "ultra")
    assert r.returncode == 2 and "invalid choice" in r.stderr
    r = run_cli("benchmark", "--out", str(tmp_path / "z"), "--eevee-samples", "0")
    assert r.returncode != 0 and r.stderr.startswith("nubis: error:") and "--eevee-samples" in r.stderr, r.stderr
    assert not (tmp_path / "z").exists()


def test_benchmark_of_a_layered_sky_times_its_lowest_layer_alone_first(tmp_path):
    """`benchmark` of a layered sky (docs/layers.md): the lowest layer alone on the same view, then the whole
    sky, in one run; the whole sky marches both halves of the view from between the layers, and nothing
    between them."""
    out = tmp_path / "layers"
    r = run_cli("benchmark", "--preset", "altocumulus_over_stratocumulus", "--out", str(out), "--width", "48",
                "--height", "27")  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "the lowest layer alone ('Layer 1')" in r.stdout.strip().splitlines()[-1], r.stdout
    whole = json.loads((out / "benchmark.json").read_text())
    lowest = json.loads((out / "lowest_layer" / "benchmark.json").read_text())
    assert whole["baseline_redraw_ms"] == lowest["redraw_ms"] and whole["redraw_ms"] > 0
    deck, both = lowest["fetches"]["coarse_to_fine"], whole["fetches"]["coarse_to_fine"]
    # Measured 2026-12-06 at 48x27: 11.6 view samples a pixel for the deck, 20.5 for both layers: the thinner
    # altocumulus, stepped at the deck's step length, adds fewer than the deck's own (docs/layers.md#step-length).
    assert 1.5 * deck["view_samples_per_pixel"] < both["view_samples_per_pixel"] < 1.9 * deck["view_samples_per_pixel"]
    assert {p.name for p in (out / "lowest_layer").iterdir()} == {"benchmark.json", "naive.png", "converged.png"}


def test_benchmark_prints_a_table_and_writes_its_report(tmp_path):
    out = tmp_path / "bench"
    r = run_cli("benchmark", "--out", str(out), "--width", "64", "--height", "36", "--eevee-samples", "1")
    assert r.returncode == 0, r.stderr
    assert "naive / redraw" in r.stdout and "EEVEE / redraw" in r.stdout
    assert r.stdout.strip().splitlines()[-1].startswith("benchmarked default at 64x36 (standard)")
    report = json.loads((out / "benchmark.json").read_text())
    assert "EEVEE, 1 sample," in r.stdout and report["eevee_samples"] == 1
    for key in ("naive_ms", "redraw_ms", "eevee_ms"):
        assert report[key] > 0
    f = report["fetches"]
    # Coarse to fine reads fewer 3D textures than the naive march's full sample at every step.
    assert 0 < f["coarse_to_fine"]["fetches_3d_per_pixel"] < 0.8 * f["naive"]["fetches_3d_per_pixel"]
    assert report["converged_psnr_db"] > 30
    assert {p.name for p in out.iterdir()} == {"benchmark.json", "naive.png", "converged.png", "eevee.png"}
