"""The validation report against the real Sionna RT (quick subset), with its tolerances.

These tests fail CI when a tolerance breaks: matched paths within 1e-6 in delay, 0.1 dB for
line of sight and reflections, 0.5 dB for diffraction in compat mode, and no path that
Sionna finds and wavepaths does not. The known disagreements run as strict expected
failures: the day Sionna RT agrees with the exact solution on one of them, its test fails.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

pytestmark = pytest.mark.sionna


def _sionna_or_skip():
    from wavepaths.errors import DependencyError
    from wavepaths.validation.sionna_env import ensure_sionna

    try:
        ensure_sionna()
    except DependencyError as exc:  # pragma: no cover - CI installs Sionna RT
        pytest.skip(f"Sionna RT is not usable here: {exc}")


@pytest.fixture(scope="module")
def quick_report(tmp_path_factory):
    _sionna_or_skip()
    from wavepaths.validation.report import run_validation

    out = tmp_path_factory.mktemp("validation")
    summary = run_validation(str(out), quick=True)
    return out, summary


def test_quick_validation_passes_its_tolerances(quick_report):
    out, summary = quick_report
    bad = [(c["name"], pol, r["violations"]) for c in summary["cases"] for pol, r in c["polarizations"].items()
           if not r["passed"]]
    assert not bad, bad
    assert summary["passed"]
    # not vacuous: every case matched paths of every kind it should have
    kinds = set()
    for c in summary["cases"]:
        for r in c["polarizations"].values():
            assert r["comparison_compat"]["matched"] > 0
            kinds |= set(r["comparison_compat"]["by_kind"])
    assert {"LOS", "R", "D"} <= kinds
    # and recomputed from the per-kind figures, not only the report's verdict: no matched path
    # with a gain difference that is not a number (an amplitude of 0 or NaN on one side), and
    # line of sight and reflections within their tolerance (the known exceptions are diffracted)
    from wavepaths.validation.report import TOLERANCES

    for c in summary["cases"]:
        for pol, r in c["polarizations"].items():
            for kind, v in r["comparison_compat"]["by_kind"].items():
                assert v["gain_diff_db"]["non_finite"] == 0, (c["name"], pol, kind)
                if "D" not in kind:
                    assert v["gain_diff_db"]["max"] <= TOLERANCES["gain_db_los_reflection"], (c["name"], pol, kind)
    d = json.loads((out / "validation.json").read_text())
    assert d["cases"] and (out / "report.html").stat().st_size > 50_000  # tables and embedded plots


def test_validation_json_is_strict_and_the_report_is_rebuilt_from_it(quick_report):
    import re

    from wavepaths.validation.figures import report_figures

    out, summary = quick_report

    def refuse(token):
        raise ValueError(f"not JSON: {token}")

    d = json.loads((out / "validation.json").read_text(), parse_constant=refuse)  # as JSON.parse reads it
    assert d == summary
    page = (out / "report.html").read_text()
    embedded = re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", page)
    assert sorted(embedded) == sorted(report_figures(d).values())


def test_the_exact_solutions_decide_who_matches(quick_report):
    _, summary = quick_report
    exact = summary["exact_comparison"]
    assert exact["passed"], exact["violations"]
    assert summary["passed"] == (summary["cases_passed"] and exact["passed"] and summary["coverage_passed"])
    known = exact["known_disagreements"]
    for k in ("hard-polarisation-coefficient", "reflection-boundary-jump", "diffraction-between-objects"):
        assert known[k]["matches_exact"] == "wavepaths UTD", (k, known[k])


def test_lines_record_each_engines_paths_and_sionnas_delay_floor(quick_report):
    """Each boundary line says how many paths of each kind each engine kept, and what Sionna's
    float32 delays cost there: an engine missing a mechanism's paths (Sionna on the wedge line,
    a review found) is off the exact solution for that reason, not for its coefficients."""
    out, summary = quick_report
    for name, line in summary["lines"].items():
        n = len(line["phi_deg"])
        counts = line["path_counts"]
        for field in ("soft", "hard"):
            mine = counts["wavepaths"][field]
            assert mine["D"] == n and mine["LOS"] > 0 and mine["R"] > 0, (name, field, mine)  # one diffraction each
            theirs = counts["Sionna RT"][field]
            assert set(theirs) == {"LOS", "R", "D"} and theirs["LOS"] <= n
            floor = line["sionna_delay_phase_rad"][field]
            assert 0 < floor["rms_rad"] <= floor["max_rad"] < 1.0 and floor["paths"] == sum(theirs.values())
            # wavepaths' own UTD with float32-rounded delays: the floor moves a correct model off too
            assert floor["utd_with_these_delays"]["max_db"] > line["errors"]["wavepaths UTD (" + field + ")"]["max_db"]
    page = (out / "report.html").read_text()
    assert page.count("Paths kept at the") == len(summary["lines"])


def test_the_report_records_what_a_reader_needs_to_recompute_it(quick_report):
    """Receiver positions, frequency, antennas and sample counts of every case; the lines'
    geometry; the coverage maps' frequency and area (a review could not reproduce a figure)."""
    _, summary = quick_report
    for c in summary["cases"]:
        assert len(c["rx"]) == c["num_rx"] and np.isfinite(np.asarray(c["rx"], float)).all()
        assert c["frequency_hz"] > 0 and c["samples_per_src"] > 0 and c["trace_options"]["max_reflections"] == c["max_depth"]
    for name, line in summary["lines"].items():
        st = line["settings"]
        assert st["scene"] == name and st["phi_prime_deg"] == line["phi_prime_deg"]
        k = 2 * np.pi * st["frequency_hz"] / 299_792_458.0
        assert k * st["rho_m"] == pytest.approx(line["k_rho"])
        assert np.linalg.norm(st["tx"]) == pytest.approx(st["source_distance_m"])
    if summary.get("coverage"):
        assert summary["coverage"]["frequency_hz"] > 0 and len(summary["coverage"]["size"]) == 2


def test_every_sionna_path_is_found_by_wavepaths(quick_report):
    from wavepaths.validation.disagreements import SIONNA_ONLY_FAILURE

    _, summary = quick_report
    for c in summary["cases"]:
        for r in c["polarizations"].values():
            assert not [x for x in r["only_sionna"] if x["reason"] == SIONNA_ONLY_FAILURE], c["name"]


def test_wavepaths_utd_matches_the_exact_solutions(quick_report):
    _, summary = quick_report
    for name, line in summary["lines"].items():
        for pol in ("soft", "hard"):
            err = line["errors"][f"wavepaths UTD ({pol})"]
            # point source 10 km away instead of a plane wave, k rho ~ 73
            assert err["max_complex_error"] < 0.02, (name, pol, err)
            assert err["median_db"] < 0.01, (name, pol, err)
            # its diffracted paths alone against the exact field minus its geometrical optics: the
            # coefficient itself (measured 0.0008-0.0045 dB and at most 3e-4 on the three lines)
            d = line["diffracted_errors"][f"wavepaths UTD ({pol})"]
            assert d["receivers_without"] == 0 and d["max_db"] < 0.05 and d["max_complex_error"] < 2e-3, (name, pol, d)


@pytest.mark.xfail(strict=True, reason="known disagreement 'hard-polarisation-coefficient' (validation/known.py)")
def test_known_sionna_hard_polarisation_matches_exact_half_plane(quick_report):
    _, summary = quick_report
    err = summary["lines"]["half_plane"]["errors"]["Sionna RT (hard)"]
    assert err["max_db"] < 1.0


@pytest.mark.xfail(strict=True, reason="known disagreement 'reflection-boundary-jump' (validation/known.py)")
def test_known_sionna_soft_polarisation_matches_exact_half_plane(quick_report):
    _, summary = quick_report
    err = summary["lines"]["half_plane"]["errors"]["Sionna RT (soft)"]
    assert err["max_db"] < 1.0


@pytest.mark.xfail(strict=True, reason="known disagreement 'hard-polarisation-coefficient' (validation/known.py)")
def test_known_textbook_utd_equals_sionna_for_diffraction(quick_report):
    _, summary = quick_report
    worst = 0.0
    for c in summary["cases"]:
        for r in c["polarizations"].values():
            for v in r["textbook_diffraction_gain_diff_db"].values():
                if v["max"] is not None:
                    worst = max(worst, v["max"])
    assert worst < 0.5


@pytest.mark.xfail(strict=True, reason="known disagreement 'diffraction-between-objects' (validation/known.py)")
def test_known_sionna_diffracts_on_an_edge_of_two_objects_as_its_exact_sector(quick_report):
    _, summary = quick_report
    for field in ("soft", "hard"):
        err = summary["lines"]["wedge_awning"]["diffracted_errors"][f"Sionna RT ({field})"]
        assert err["receivers"] > 0 and err["max_db"] < 1.0, (field, err)


def test_compat_mode_reproduces_sionna_on_the_half_plane_line(quick_report):
    # the half-plane only: with the quick report's 1e6 samples Sionna keeps no diffracted path on
    # the wedge line, and on the awning's line it diffracts with another wedge than the sector
    _, summary = quick_report
    for name, line in [("half_plane", summary["lines"]["half_plane"])]:
        for pol in ("soft", "hard"):
            sn = line["errors"][f"Sionna RT ({pol})"]
            cp = line["errors"][f"wavepaths compat=sionna ({pol})"]
            assert abs(sn["median_db"] - cp["median_db"]) < 0.1, (name, pol)
            # and the diffracted paths alone, judged against the exact field minus its geometrical
            # optics: the same coefficient error (46 / 35 dB measured, hard / soft)
            sn, cp = (line["diffracted_errors"][f"{e} ({pol})"] for e in ("Sionna RT", "wavepaths compat=sionna"))
            assert sn["receivers_without"] == 0 and sn["max_db"] > 10.0, (pol, sn)
            assert abs(sn["max_db"] - cp["max_db"]) < 0.5 and abs(sn["median_db"] - cp["median_db"]) < 0.1, (pol, sn, cp)


def test_compat_mode_reproduces_sionna_point_by_point_on_the_half_plane_line(quick_report):
    # point by point, as complex fields normalised to the incident one: median 0.014 and 90th
    # percentile 0.08 measured (Sionna's float32 geometry and its sampled reflection points),
    # beside the one listed exception at phi = 359 deg, where Sionna sees a line of sight
    # through the screen (known disagreement 'sionna-los-skips-last-segment-fraction')
    _, summary = quick_report
    line = summary["lines"]["half_plane"]
    phi = np.asarray(line["phi_deg"])
    for pol in ("soft", "hard"):
        c = line["curves"]
        sn = np.asarray(c[f"Sionna RT ({pol})"]["re"]) + 1j * np.asarray(c[f"Sionna RT ({pol})"]["im"])
        cp = (np.asarray(c[f"wavepaths compat=sionna ({pol})"]["re"])
              + 1j * np.asarray(c[f"wavepaths compat=sionna ({pol})"]["im"]))
        d = np.abs(sn - cp)
        listed = phi == 359.0
        assert d[listed].min() > 0.9, (pol, d[listed])  # the exception is still there (else drop it)
        d = d[~listed]
        assert np.median(d) < 0.03 and np.percentile(d, 90) < 0.15 and d.max() < 0.25, (
            pol, np.median(d), np.percentile(d, 90), d.max(), phi[~listed][np.argmax(d)])


def test_coverage_maps_of_both_engines_agree_on_the_street_canyon(quick_report):
    _, summary = quick_report
    cov = summary["coverage"]
    no_diff = cov["runs"]["no_diffraction"]
    assert no_diff["cells_compared"] > 200
    # same quantity (power sum of LOS + reflections): only Sionna's sampling noise and cell averaging differ
    assert abs(no_diff["median_db"]) < 0.5
    with_diff = cov["runs"]["diffraction"]
    assert with_diff["cells_compared"] >= no_diff["cells_compared"]  # diffraction lights the shadowed cells
    assert abs(with_diff["median_db"]) < 1.0


def test_the_coverage_difference_is_explained_and_vanishes_like_for_like(quick_report):
    """The 2-4 dB spread of the two engines' maps is made of Sionna's sampling noise, cell
    averaging and two model differences (its radio map's paths, its coefficient). Measured at 4 m
    cells: without diffraction cell averaging takes the std from 2.09 to 0.12 dB; with it the
    like-for-like maps agree to 0.56 dB against Sionna at 10x samples (from 4.18)."""
    _, summary = quick_report
    assert summary["coverage_passed"]
    for name, run in summary["coverage"]["runs"].items():
        like, rows = run["like_for_like"], run["decomposition"]["rows"]
        assert like["passed"] and like["cells"] == run["cells_compared"], name
        baseline = rows[0]
        assert baseline["std_db"] == pytest.approx(run["std_db"]) and baseline["cells"] == run["cells_compared"]
        assert like["std_db"] < baseline["std_db"] / 3, (name, like, baseline)
    noise = summary["coverage"]["runs"]["no_diffraction"]["decomposition"]["sionna_seed_noise_db"]
    assert noise < 0.01  # a fixed lattice of rays: the seed changes nothing without diffraction
    noise = summary["coverage"]["runs"]["diffraction"]["decomposition"]["sionna_seed_noise_db"]
    assert 0.3 < noise < 3.0  # a few diffracted samples per cell
    # each model difference alone leaves most of the spread (2.2 dB and 4.3 dB measured)
    rows = {r["wavepaths"]: r for r in summary["coverage"]["runs"]["diffraction"]["decomposition"]["rows"]}
    alone = [r for w, r in rows.items() if "compat='sionna', with reflections" in w or "textbook UTD, no reflection" in w]
    assert len(alone) == 2 and all(r["std_db"] > 2 * summary["coverage"]["runs"]["diffraction"]["like_for_like"]["std_db"]
                                   for r in alone)


@pytest.mark.xfail(strict=True, reason="known disagreement 'sionna-los-skips-last-segment-fraction' "
                                        "(validation/known.py)")
def test_known_sionna_sees_no_line_of_sight_through_a_screen_near_the_receiver(tmp_path):
    # the half-plane line's transmitter 10 km away at phi' = 60 deg; the receiver 1 m from the
    # edge at phi = 359 deg, behind the screen, which crosses the line of sight 2.0 cm before it
    _sionna_or_skip()
    from wavepaths.scene import load_scene, write_mitsuba_xml
    from wavepaths.search import TraceOptions, trace
    from wavepaths.validation.lines import S_PRIME, _geometry
    from wavepaths.validation.sionna_runner import run_sionna_paths

    scene = load_scene("half_plane")
    xml = str(tmp_path / "half_plane.xml")
    write_mitsuba_xml(scene, xml)
    to_xyz, _, phi_p = _geometry("half_plane")
    tx = S_PRIME * to_xyz(np.deg2rad(np.array([phi_p])))
    rx = to_xyz(np.deg2rad(np.array([359.0])))
    crossing = tx[0] + tx[0, 1] / (tx[0, 1] - rx[0, 1]) * (rx[0] - tx[0])
    assert crossing[2] < 0 and np.linalg.norm(rx[0] - crossing) < 0.03  # the screen (z < 0) blocks the line
    wp = trace(scene, tx, rx, TraceOptions(max_reflections=1, diffraction=True, diffraction_reflections=0))
    assert not (wp.depth == 0).any()  # wavepaths: no line of sight
    sn = run_sionna_paths(xml, tx, rx, frequency_hz=3.5e9, max_depth=1, diffraction=True, edge_diffraction=True)
    assert not (sn.num_interactions == 0).any()


@pytest.mark.xfail(strict=True, reason="known disagreement 'sionna-dr-depends-on-max-depth' (validation/known.py)")
def test_known_sionna_d_r_coefficient_does_not_depend_on_max_depth():
    _sionna_or_skip()
    from wavepaths.search.paths import InteractionType as IT
    from wavepaths.validation.sionna_runner import builtin_scene_path, run_sionna_paths

    xml = builtin_scene_path("simple_street_canyon")
    tx, rx = np.array([[-40.0, 0.0, 10.0]]), np.array([[20.0, 2.0, 1.5]])
    runs = [run_sionna_paths(xml, tx, rx, frequency_hz=3.5e9, max_depth=d, diffraction=True) for d in (2, 3)]
    gains = []
    for sn in runs:
        dr = (sn.num_interactions == 2) & (sn.interactions[:, 0] == IT.DIFFRACTION) & (sn.interactions[:, 1] == IT.REFLECTION)
        key = np.round(sn.tau[dr] * 299_792_458.0, 3)
        gains.append(dict(zip(key.tolist(), (20 * np.log10(np.abs(sn.a[dr]))).tolist())))
    common = set(gains[0]) & set(gains[1])
    assert len(common) >= 3
    assert max(abs(gains[0][k] - gains[1][k]) for k in common) < 0.1
