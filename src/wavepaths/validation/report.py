"""``wavepaths validate``: the validation report against Sionna RT and exact solutions.

For each case (:mod:`wavepaths.validation.cases`) both engines load the same Mitsuba XML
file and trace the same transmitters, receivers, antennas and path types. wavepaths runs
twice on the same geometry: with the textbook diffraction model and with
``compat="sionna"``; matched paths are compared like for like (compat), and the textbook
model's diffraction differences are reported beside them. Receiver lines across the
shadow and reflection boundaries show who agrees with the exact solutions.

Tolerances held (Sionna computes in float32, wavepaths in float64):

* delays: 1e-6 relative;
* |a| of line-of-sight and reflected paths: 0.1 dB;
* |a| of diffracted paths, compat mode: 0.5 dB;
* no path may be found by Sionna and not by wavepaths;
* against the exact solutions (the arbiter; Sionna RT is a peer): wavepaths' UTD within
  0.5 dB in |u| and 0.02 in complex u on every boundary line and polarisation
  (:mod:`wavepaths.validation.verdict`, which also says which engine matches where the two
  disagree);
* coverage maps like for like (the same paths, Sionna's diffraction coefficient, wavepaths
  averaged over each cell, Sionna with 10x its samples): the difference's std within 1.5 dB
  and its median within 0.5 dB, with and without diffraction
  (:mod:`wavepaths.validation.coverage_compare`, which also measures what the difference of
  the two engines' own maps is made of).

The report passes when every case, the exact-solution comparison and the like-for-like
coverage comparison pass.

``validation.json`` is strict JSON: a non-finite number (-inf dB where no path reaches a
receiver, NaN where a coverage cell is not compared) is written ``null``
(:mod:`wavepaths.validation.json_io`). It holds everything the figures are drawn from (the
boundary lines' complex fields, the coverage maps), and ``report.html`` is written from the
file as read back (:func:`write_report`), so the report can be rebuilt from the JSON alone.
"""

from __future__ import annotations

import html
import json
import os
import time

import numpy as np

from ..fields import FieldConfig, compute_fields
from ..scene import load_scene, write_mitsuba_xml
from ..search import TraceOptions, trace
from .cases import Case, default_cases
from .compare import compare_paths, total_gain_db
from .disagreements import (
    MATCHED_MULTI_OBJECT_EDGE,
    MATCHED_NON_MANIFOLD_EDGE,
    SIONNA_ONLY_FAILURE,
    _explainer,
    _matched_wedge_difference,
    _multi_object_dihedra,
    _non_manifold_dihedra,
    _sionna_collapsed_free_edge,
)
from .figures import report_figures
from .json_io import write_json
from .known import KNOWN_DISAGREEMENTS
from .verdict import EXACT_TOLERANCES, HELD_ENGINE, exact_comparison, known_disagreement_verdicts

TOLERANCES = {"delay_rel": 1e-6, "gain_db_los_reflection": 0.1, "gain_db_diffraction_compat": 0.5,
              **EXACT_TOLERANCES}


def gain_violation(gain_diff_db: float, tol_db: float) -> bool:
    """Whether a matched path's gain difference [dB] breaks the tolerance ``tol_db``: beyond
    it, and also where it is not a number, +-inf (an amplitude of 0 in one engine only) or NaN
    (a NaN amplitude). A coefficient that collapsed to 0 is a failure, never skipped."""
    return not abs(gain_diff_db) <= tol_db


def _scene_file(case: Case, out_dir: str) -> str:
    if case.scene.startswith("sionna:"):
        from .sionna_runner import builtin_scene_path

        return builtin_scene_path(case.scene.split(":", 1)[1])
    path = os.path.join(out_dir, "scenes", case.scene, f"{case.scene}.xml")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    write_mitsuba_xml(load_scene(case.scene), path)
    return path


def run_case(case: Case, out_dir: str) -> dict:
    """Run one case on both engines; return its JSON-ready result."""
    from .sionna_runner import run_sionna_paths

    xml = _scene_file(case, out_dir)
    scene = load_scene(xml)
    opts = TraceOptions(max_reflections=case.max_depth, diffraction=True,
                        diffraction_reflections=max(case.max_depth - 1, 0))
    t0 = time.perf_counter()
    paths = trace(scene, case.tx, case.rx, opts)
    wp_time = time.perf_counter() - t0
    result = {"name": case.name, "scene": case.scene, "scene_file": xml, "note": case.note,
              "tx": case.tx.tolist(), "num_rx": len(case.rx), "rx": case.rx.tolist(), "max_depth": case.max_depth,
              "edge_diffraction": case.edge_diffraction, "frequency_hz": case.frequency_hz,
              "samples_per_src": case.samples_per_src, "antennas": "isotropic, both ends, V then H",
              "trace_options": opts.to_dict(),
              "wavepaths_paths": len(paths), "wavepaths_time_s": wp_time, "polarizations": {}}
    from ..em.antennas import Antenna

    for pol in case.polarizations:
        ant = Antenna("iso", pol)
        t0 = time.perf_counter()
        compat = compute_fields(scene, paths, FieldConfig(case.frequency_hz, "utd", "sionna", tx_antenna=ant, rx_antenna=ant))
        fields_time = time.perf_counter() - t0
        textbook = compute_fields(scene, paths, FieldConfig(case.frequency_hz, "utd", tx_antenna=ant, rx_antenna=ant))
        sn = run_sionna_paths(xml, case.tx, case.rx, frequency_hz=case.frequency_hz, max_depth=case.max_depth,
                              diffraction=True, edge_diffraction=case.edge_diffraction,
                              samples_per_src=case.samples_per_src,
                              tx_antenna=("iso", pol), rx_antenna=("iso", pol))
        explain = _explainer(scene, paths, sn, case)
        comp = compare_paths(paths, compat.a, sn, explain=explain)
        comp_tb = compare_paths(paths, textbook.a, sn, explain=explain)
        m, n = len(case.tx), len(case.rx)
        matched_w = np.array([x.wp_index for x in comp.matches], dtype=int)
        g_sn = total_gain_db(sn.tx_index, sn.rx_index, sn.a, sn.tau, case.frequency_hz, m, n)
        g_wp_matched = total_gain_db(paths.tx_index[matched_w], paths.rx_index[matched_w], compat.a[matched_w],
                                     paths.delays[matched_w], case.frequency_hz, m, n)
        g_wp_all = textbook.path_gain_db()
        summary = comp.summary()
        violations = []
        topo = _multi_object_dihedra(scene)
        non_manifold = _non_manifold_dihedra(scene)
        different_wedge = 0
        non_manifold_wedge = 0
        collapsed_free_edge = 0
        known_dr = 0
        for mm in comp.matches:
            if mm.kinds == "D-R" and case.max_depth >= 3:
                known_dr += 1  # known disagreement 'sionna-dr-depends-on-max-depth'
                continue
            wedge = (_matched_wedge_difference(paths, mm.wp_index, topo, non_manifold)
                     if "D" in mm.kinds else None)
            if wedge == MATCHED_MULTI_OBJECT_EDGE:
                # wavepaths' true dihedron takes another object's face on this edge; Sionna's wedge is
                # its mesh's own two faces: a different exterior angle, a known topology difference
                different_wedge += 1
                continue
            if abs(mm.delay_rel_error) > TOLERANCES["delay_rel"]:
                violations.append(f"delay {mm.kinds} rx {mm.rx}: {mm.delay_rel_error:.2e}")
            tol = TOLERANCES["gain_db_diffraction_compat"] if "D" in mm.kinds else TOLERANCES["gain_db_los_reflection"]
            if gain_violation(mm.gain_diff_db, tol):
                if wedge == MATCHED_NON_MANIFOLD_EDGE:
                    # three or more faces of one mesh on the edge; Sionna's wedge is one pair of them
                    # (known disagreement 'non-manifold-edge-wedge')
                    non_manifold_wedge += 1
                elif "D" in mm.kinds and _sionna_collapsed_free_edge(scene, paths, mm, sn, compat.a):
                    # Sionna's screen became a flat wedge (n = 1) in float32: its coefficient vanishes
                    # (known disagreement 'sionna-free-edge-collapses-to-flat')
                    collapsed_free_edge += 1
                else:
                    violations.append(f"|a| {mm.kinds} rx {mm.rx}: {mm.gain_diff_db:+.3f} dB")
        failures = [x for x in comp.only_sionna if x["reason"] == SIONNA_ONLY_FAILURE]
        if failures:
            violations.append(f"{len(failures)} path(s) found by Sionna only")
        textbook_d = comp_tb.summary()["by_kind"]
        result["polarizations"][pol] = {
            "comparison_compat": summary,
            "matched_on_multi_object_edges": different_wedge,
            "matched_on_non_manifold_edges": non_manifold_wedge,
            "matched_on_collapsed_free_edges": collapsed_free_edge,
            "matched_d_r_at_depth_3_not_held": known_dr,
            "textbook_diffraction_gain_diff_db": {k: v["gain_diff_db"] for k, v in textbook_d.items() if "D" in k},
            "only_wavepaths": comp.only_wavepaths[:200],
            "only_sionna": comp.only_sionna[:200],
            "total_gain_db": {"sionna": g_sn.tolist(), "wavepaths_matched_compat": g_wp_matched.tolist(),
                              "wavepaths_all_textbook": g_wp_all.tolist()},
            "total_gain_diff_db_matched": _finite_max(_finite_diff(g_wp_matched, g_sn)),
            "sionna_paths": int(len(sn.tx_index)),
            "sionna_time_s": sn.elapsed_s,
            "sionna_warmup_s": sn.warmup_s,
            "wavepaths_fields_time_s": fields_time,
            "violations": violations,
            "passed": not violations,
        }
    result["passed"] = all(v["passed"] for v in result["polarizations"].values())
    return result


def _finite_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    both = np.isfinite(a) & np.isfinite(b)
    return np.abs(a[both] - b[both])


def _finite_max(x: np.ndarray):
    x = np.asarray(x)
    x = x[np.isfinite(x)]
    return float(x.max()) if len(x) else None


def _versions() -> dict:
    from .._machine import host_versions

    out = host_versions()
    try:
        from .sionna_env import sionna_version

        out["sionna-rt"] = sionna_version()
        import drjit
        import mitsuba

        out["mitsuba"] = mitsuba.__version__
        out["drjit"] = drjit.__version__
    except Exception:  # pragma: no cover - reported as missing
        pass
    return out


def _fmt(x, spec=".3g"):
    return "-" if x is None else format(x, spec)


def _line_paths_text(line: dict) -> str:
    """The paths each engine kept on a boundary line (line of sight / reflections / diffractions
    by the edge), and the phase floor of Sionna's float32 delays there: an engine missing a
    mechanism's paths, or carrying that floor, is off the exact solution for that reason, not
    for its coefficients. Empty for a summary written before these were recorded."""
    counts = line.get("path_counts") or {}
    if not counts:
        return ""
    e = html.escape
    cells = "; ".join(f"{e(engine)} ({e(field)}): {c['LOS']} / {c['R']} / {c['D']}"
                      for engine, by_field in counts.items() for field, c in by_field.items())
    text = f"<p>Paths kept at the {len(line['phi_deg'])} receivers (line of sight / reflections / diffractions by the edge): {cells}."
    phase = {f: v for f, v in (line.get("sionna_delay_phase_rad") or {}).items() if v.get("rms_rad") is not None}
    if phase:
        text += (" Sionna's delays are float32: against the float64 lengths of its own paths (10 km from the source) "
                 "they put " + "; ".join(f"{e(f)}: {v['rms_rad']:.3f} rad rms, {v['max_rad']:.3f} max"
                                          for f, v in phase.items())
                 + " into its path phases. Rounded the same way, wavepaths' own UTD delays take it "
                 + "; ".join(f"{e(f)}: {v['utd_with_these_delays']['max_db']:.2f} dB, "
                             f"{v['utd_with_these_delays']['max_complex_error']:.3f} complex"
                             for f, v in phase.items() if "utd_with_these_delays" in v)
                 + " off the exact solution: a floor under Sionna's errors on this line.")
    return text + "</p>"


def _line_diffracted_html(name: str, line: dict, exact: dict) -> str:
    """The table of each engine's diffracted paths alone against the exact solution minus its
    geometrical optics (``lines.diffracted_errors``); empty for a summary without it."""
    errors = line.get("diffracted_errors")
    if not errors:
        return ""
    e = html.escape
    verdicts = exact["lines"].get(name, {})
    rows = []
    for key, v in errors.items():
        engine, field = key.rsplit(" (", 1)
        judged = verdicts.get(field.rstrip(")"), {}).get("diffracted_engines", {}).get(engine)
        within = "-" if judged is None else ("yes" if judged["within_tolerance"] else "no")
        rows.append(f"<tr><td>{e(key)}</td><td>{v['receivers']} of {v['receivers'] + v['receivers_without']}</td>"
                    f"<td>{_fmt(v['max_db'])}</td><td>{_fmt(v['median_db'])}</td><td>{_fmt(v['max_complex_error'])}</td>"
                    f"<td>{within}</td></tr>")
    who = "; ".join(f"{field}: <b>{e(v['diffracted_matches_exact'])}</b>" for field, v in verdicts.items()
                    if "diffracted_matches_exact" in v)
    return ("<p>The diffraction coefficient alone: each engine's diffracted paths against the exact solution minus "
            "its geometrical optics (incident and reflected plane waves), at the receivers where the engine has a "
            "diffracted path, so that a missing reflection or a delay floor does not count. Matches: " + who + "</p>"
            "<table><tr><th>engine (polarisation)</th><th>receivers with a diffracted path</th><th>max |u_d| error [dB]"
            "</th><th>median [dB]</th><th>max complex error</th><th>within tolerance</th></tr>" + "".join(rows)
            + "</table>")


def _coverage_decomposition_html(cov: dict) -> str:
    """What the difference of the two engines' maps is made of, and the like-for-like verdict
    (``coverage_compare._decomposition``); empty for a summary without them."""
    runs = {k: r for k, r in cov["runs"].items() if "decomposition" in r}
    if not runs:
        return ""
    e = html.escape
    parts = ["<h3>What the difference is made of</h3><p>Four things separate the two maps, each measured here: "
             "Sionna's sampling noise (two of its maps with different seeds; without diffraction its rays leave on a "
             "fixed lattice and the seed changes nothing); cell averaging (Sionna averages the power over the cell, a "
             "part inside a building counting as zero, wavepaths samples the centre); the path set (Sionna's radio map "
             "diffracts only from the transmitter to an edge to the cell, with no reflection before or after); and "
             "the diffraction coefficient (Sionna's combination, which the boundary lines above judge against the "
             "exact solutions). Like for like, with the last two matched and wavepaths averaged over each cell, the "
             f"maps must agree with Sionna at {cov.get('reference_factor', 10)} times its samples within "
             f"{runs[next(iter(runs))]['like_for_like']['tolerances']['std_db']} dB std and "
             f"{runs[next(iter(runs))]['like_for_like']['tolerances']['abs_median_db']} dB median.</p>"]
    for name, r in runs.items():
        d, like = r["decomposition"], r["like_for_like"]
        verdict = "pass" if like["passed"] else "FAIL"
        parts.append(f"<p><b>{e(name.replace('_', ' '))}</b>: Sionna's seed-to-seed noise "
                     f"{_fmt(d['sionna_seed_noise_db'])} dB rms; like for like: std {_fmt(like['std_db'])} dB, median "
                     f"{_fmt(like['median_db'])} dB over {like['cells']} cells: <b>{verdict}</b>; "
                     f"{r.get('cells_sionna_inside_objects', 0)} cells whose centre lies inside a building have a "
                     "Sionna value and none from wavepaths (not compared).</p>")
        parts.append("<table><tr><th>wavepaths map</th><th>Sionna map</th><th>std of the difference [dB]</th>"
                     "<th>median [dB]</th><th>cells</th></tr>" + "".join(
                         f"<tr><td style='text-align:left'>{e(row['wavepaths'])}</td><td style='text-align:left'>"
                         f"{e(row['sionna'])}</td><td>{_fmt(row['std_db'])}</td><td>{_fmt(row['median_db'])}</td>"
                         f"<td>{row['cells']}</td></tr>" for row in d["rows"]) + "</table>")
    return "".join(parts)


def _verdict_text(summary: dict) -> str:
    exact = summary["exact_comparison"]
    cases = "pass" if summary["cases_passed"] else "FAIL"
    held = "pass" if exact["passed"] else "FAIL: " + "; ".join(exact["violations"][:3])
    text = (f"path-by-path comparison with Sionna RT: {cases}; {HELD_ENGINE} against the exact solutions: "
            f"{html.escape(held)}")
    if "coverage_passed" in summary:
        text += f"; coverage maps like for like: {'pass' if summary['coverage_passed'] else 'FAIL'}"
    return text


def _within_text(exact: dict, line: str, key: str) -> str:
    """'yes' / 'no' for an engine the exact comparison measures, '-' (not judged) for the others."""
    engine, field = key.rsplit(" (", 1)
    v = exact["lines"].get(line, {}).get(field.rstrip(")"), {}).get("engines", {}).get(engine)
    return "-" if v is None else ("yes" if v["within_tolerance"] else "no")


def _known_verdict_html(k: dict, exact: dict) -> str:
    v = exact["known_disagreements"].get(k["id"])
    if v is None or v["matches_exact"] is None:
        return f"not measured here; documented: {html.escape(k['who_matches_exact'])}"
    return f"<b>{html.escape(v['matches_exact'])}</b> <span class=small>({html.escape(v['detail'])})</span>"


def write_html(summary: dict, figures: dict, path: str) -> None:
    """The HTML report: versions, tolerances, per-case tables and plots, known disagreements."""
    e = html.escape
    rows = []
    for c in summary["cases"]:
        for pol, r in c["polarizations"].items():
            s = r["comparison_compat"]
            rows.append(
                f"<tr class={'ok' if r['passed'] else 'bad'}><td>{e(c['name'])}</td><td>{pol}</td><td>{s['matched']}</td>"
                f"<td>{s['only_wavepaths']}</td><td>{s['only_sionna']}</td>"
                f"<td>{_fmt(s['delay_rel_error']['max'])}</td><td>{_fmt(s['gain_diff_db']['median'])}</td>"
                f"<td>{_fmt(s['gain_diff_db']['max'])}</td><td>{_fmt(r['total_gain_diff_db_matched'])}</td>"
                f"<td>{_fmt(c['wavepaths_time_s'])}</td><td>{_fmt(r['sionna_time_s'])}</td>"
                f"<td>{'pass' if r['passed'] else 'FAIL: ' + e('; '.join(r['violations'][:3]))}</td></tr>")
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>wavepaths validation</title><style>",
        "body{font-family:system-ui,sans-serif;max-width:1250px;margin:2em auto;color:#222}"
        "table{border-collapse:collapse;font-size:13px;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 7px;text-align:right}"
        "th{background:#f0f0f0}td:first-child{text-align:left}tr.bad{background:#fdd}tr.ok td:last-child{color:#070}"
        "code{background:#f4f4f4;padding:1px 3px}img{max-width:100%}.small{font-size:12px;color:#555}",
        "</style></head><body>",
        "<h1>wavepaths validation against Sionna RT and exact solutions</h1>",
        f"<p>Generated {e(summary['generated'])} by <code>wavepaths validate{' --quick' if summary['quick'] else ''}</code>. "
        f"Overall: <b>{'PASS' if summary['passed'] else 'FAIL'}</b> ({_verdict_text(summary)}).</p>",
        "<h2>Versions and machine</h2><table>" + "".join(
            f"<tr><th>{e(k)}</th><td>{e(str(v))}</td></tr>" for k, v in summary["versions"].items()) + "</table>",
        "<h2>Tolerances</h2><p>Sionna RT computes in float32, wavepaths in float64. Matched paths must agree within "
        f"{TOLERANCES['delay_rel']:g} relative in delay, {TOLERANCES['gain_db_los_reflection']} dB in |a| for line of sight "
        f"and reflections, {TOLERANCES['gain_db_diffraction_compat']} dB for diffraction when wavepaths reproduces Sionna's "
        "diffraction combination (<code>compat='sionna'</code>); every path Sionna finds must be found by wavepaths. "
        "Paths are matched by interaction sequence and vertex positions (within 2 cm), not by order.</p>"
        "<p>The exact solutions are the arbiter, Sionna RT is a peer: on every boundary line and polarisation "
        f"wavepaths' UTD must stay within {summary['tolerances']['exact_max_db']} dB of the exact |u| where it is lit "
        f"(|u| &gt; 0.05) and within {summary['tolerances']['exact_max_complex_error']} of the exact complex u "
        "(a point source 10 km away stands in for the plane wave; UTD is asymptotic in 1/(k rho), k rho ~ 73). "
        "An engine within both bounds matches the exact solution. Non-finite numbers are <code>null</code> in "
        "<code>validation.json</code>.</p>",
        "<h2>Path-by-path comparison (compat mode)</h2><table><tr><th>case</th><th>pol</th><th>matched</th>"
        "<th>only wavepaths</th><th>only Sionna</th><th>max delay rel. diff</th><th>median |a| diff [dB]</th>"
        "<th>max |a| diff [dB]</th><th>max total gain diff, matched [dB]</th><th>wavepaths trace [s]</th>"
        "<th>Sionna [s]</th><th>verdict</th></tr>" + "".join(rows) + "</table>",
    ]
    parts.append("<h2>Across shadow and reflection boundaries: who matches the exact solution</h2>"
                 "<p>A transmitter 10 km away lights the edge (a plane wave); receivers on a circle around it. "
                 "|u| is the total field (line of sight, reflection, diffraction by this edge) relative to the "
                 "incident field at the edge. Black: the exact solution (Sommerfeld's half-plane; the wedge "
                 "eigenfunction series). The third line's edge is shared by two objects: a metal awning is hinged "
                 "on the wedge's edge, and the receivers lie in the sector between the wedge's lit face and the "
                 "awning, a wedge of n = 7/6 whose exact solution is the series again (the configuration of the "
                 "three_face_edge case, whose diffracted paths on that edge are exempted from the path-by-path "
                 "tolerance).</p>")
    exact = summary["exact_comparison"]
    for name, line in summary.get("lines", {}).items():
        parts.append(f"<h3>{e(name)}</h3><img src='data:image/png;base64,{figures['line_' + name]}'>")
        st = line.get("settings")
        if st:
            parts.append(f"<p class=small>{e(st['scene'])} ({e(st['material'])}), {st['frequency_hz'] / 1e9:g} GHz; "
                         f"receivers every {st['phi_step_deg']:g} degrees on a circle of {st['rho_m']:g} m around the "
                         f"edge; source at phi' = {st['phi_prime_deg']:g} degrees, {st['source_distance_m']:g} m away "
                         f"({st['tx']}); kept: {e(st['kept'])}; {e(st['antennas'])}; Sionna max_depth "
                         f"{st['sionna_max_depth']}, {st['sionna_samples_per_src']:,} samples.</p>")
        verdicts = exact["lines"].get(name, {})
        parts.append("<p>Matches the exact solution: " + "; ".join(
            f"{field}: <b>{e(v['matches_exact'])}</b>" for field, v in verdicts.items()) + "</p>")
        parts.append("<table><tr><th>engine (polarisation)</th><th>max |u| error [dB]</th><th>median [dB]</th>"
                     "<th>max complex error</th><th>within tolerance</th></tr>" + "".join(
                         f"<tr><td>{e(k)}</td><td>{_fmt(v['max_db'])}</td><td>{_fmt(v['median_db'])}</td>"
                         f"<td>{_fmt(v['max_complex_error'])}</td><td>{_within_text(exact, name, k)}</td></tr>"
                         for k, v in line["errors"].items()) + "</table>")
        parts.append(_line_diffracted_html(name, line, exact))
        parts.append(_line_paths_text(line))
    cov = summary.get("coverage")
    if cov:
        parts.append("<h2>Coverage maps</h2><p>Sionna RT's <code>RadioMapSolver</code> (ray shooting, cell-averaged, "
                     "power sum) and wavepaths' exact paths at the cell centres (power sum), same scene "
                     f"(<code>{e(str(cov['scene']))}</code>), transmitter {cov['tx']}, {cov['cell_m']} m cells at "
                     f"z = {cov['center'][2]} m, depth {cov['max_depth']}. Statistics over cells outside buildings "
                     f"where both maps exceed {cov['noise_floor_db']} dB.</p>")
        if "frequency_hz" in cov:
            parts.append(f"<p class=small>{cov['frequency_hz'] / 1e9:g} GHz; area {cov['size']} m around {cov['center']}; "
                         f"{e(cov['antennas'])}; Sionna {cov['samples_per_tx']:,} samples; {e(cov['field_model'])}.</p>")
        parts.append(f"<img src='data:image/png;base64,{figures['coverage']}'>")
        parts.append("<table><tr><th>run</th><th>cells compared</th><th>median diff [dB]</th><th>mean [dB]</th>"
                     "<th>std [dB]</th><th>95% |diff| [dB]</th><th>cells only wavepaths reaches</th>"
                     "<th>wavepaths [s]</th><th>Sionna [s] (after warm-up)</th></tr>" + "".join(
                         f"<tr><td>{e(k)}</td><td>{r['cells_compared']}</td><td>{_fmt(r['median_db'])}</td>"
                         f"<td>{_fmt(r['mean_db'])}</td><td>{_fmt(r['std_db'])}</td><td>{_fmt(r['p95_abs_db'])}</td>"
                         f"<td>{r['cells_only_wavepaths']}</td><td>{_fmt(r['wavepaths_time_s'])}</td>"
                         f"<td>{_fmt(r['sionna_time_s'])}</td></tr>" for k, r in cov["runs"].items()) + "</table>")
        parts.append(_coverage_decomposition_html(cov))
    parts.append("<h2>Known disagreements</h2><p>Which engine matches the exact solution is computed from the "
                 "boundary lines' errors above (within the tolerances on every line the disagreement shows on); "
                 "where no line of this report measures it, the documented answer is given with the test that "
                 "checks it.</p><table><tr><th>what</th><th>why</th><th>matches the exact solution</th></tr>"
                 + "".join(f"<tr><td style='text-align:left'>{e(k['what'])}</td><td style='text-align:left'>{e(k['reason'])}</td>"
                           f"<td style='text-align:left'>{_known_verdict_html(k, exact)}</td></tr>"
                           for k in summary["known_disagreements"]) + "</table>")
    parts.append("<h2>Cases</h2>")
    for c in summary["cases"]:
        settings = (f"; {c['frequency_hz'] / 1e9:g} GHz; transmitter(s) {c['tx']}; {c['antennas']} antennas; Sionna "
                    f"{c['samples_per_src']:,} samples per source" if "samples_per_src" in c else "")
        origin = ("Sionna RT's own scene" if str(c["scene"]).startswith("sionna:")
                  else "written in the report's folder, <code>scenes/</code>")
        parts.append(f"<h3>{e(c['name'])}</h3><p class=small>{e(c['note'])}. Scene file <code>{e(c['scene_file'])}</code> "
                     f"({origin}); "
                     f"{c['num_rx']} receivers (positions: <code>validation.json</code>, <code>cases[].rx</code>); "
                     f"depth {c['max_depth']}; edge diffraction in Sionna: {c['edge_diffraction']}{e(settings)}.</p>")
        if "gain_" + c["name"] in figures:
            parts.append(f"<img src='data:image/png;base64,{figures['gain_' + c['name']]}'>")
        for pol, r in c["polarizations"].items():
            bk = r["comparison_compat"]["by_kind"]
            parts.append(f"<p><b>{pol}</b>: by interaction sequence (compat): " + ", ".join(
                f"{e(k)}: {v['matched']} matched, max |a| diff {_fmt(v['gain_diff_db']['max'])} dB" for k, v in bk.items()) + "</p>")
            if r["textbook_diffraction_gain_diff_db"]:
                parts.append("<p class=small>Textbook UTD vs Sionna for the same diffracted paths: " + ", ".join(
                    f"{e(k)} max {_fmt(v['max'])} dB, median {_fmt(v['median'])} dB"
                    for k, v in r["textbook_diffraction_gain_diff_db"].items()) + "</p>")
            if r.get("matched_on_multi_object_edges"):
                parts.append(f"<p class=small>{r['matched_on_multi_object_edges']} matched diffracted path(s) lie on edges "
                             "shared by several objects: wavepaths' true dihedron (seed §3.3) differs from Sionna's "
                             "single-mesh wedge, so their coefficients are not held to the tolerance; the wedge_awning "
                             "boundary line judges that difference against the exact solution.</p>")
            if r.get("matched_on_non_manifold_edges"):
                parts.append(f"<p class=small>{r['matched_on_non_manifold_edges']} matched diffracted path(s) lie on edges "
                             "where three or more faces of one mesh meet: Sionna's wedge is one pair of them (one block's "
                             "own corner), wavepaths' the free-space sector of all of them, so their coefficients are not "
                             "held to the tolerance (known disagreement 'non-manifold-edge-wedge').</p>")
            if r.get("matched_on_collapsed_free_edges"):
                parts.append(f"<p class=small>{r['matched_on_collapsed_free_edges']} matched diffracted path(s) lie on free "
                             "edges whose Sionna wedge collapsed to a flat one (n = 1) in float32: Sionna's coefficient "
                             "vanishes where the exact half-plane solution does not (known disagreement "
                             "'sionna-free-edge-collapses-to-flat').</p>")
            reasons = r["comparison_compat"]["only_wavepaths_reasons"]
            if reasons:
                parts.append("<p class=small>Only in wavepaths: " + "; ".join(f"{v} x {e(k)}" for k, v in reasons.items()) + "</p>")
            if r["only_sionna"]:
                parts.append("<p class=small style='color:#a00'>Only in Sionna: " + "; ".join(
                    f"{e(x['kinds'])} rx {x['rx']} ({_fmt(x['length_m'], '.3f')} m)" for x in r["only_sionna"][:20]) + "</p>")
    parts.append("</body></html>")
    with open(path, "w") as f:
        f.write("\n".join(parts))


def coverage_verdict(coverage_summary: dict | None) -> bool:
    """Whether every coverage run agrees like for like (``runs.<run>.like_for_like.passed``); a run
    without that verdict, or no run, is not a pass."""
    runs = (coverage_summary or {}).get("runs", {})
    return bool(runs) and all(r.get("like_for_like", {}).get("passed", False) for r in runs.values())


def write_report(json_path: str, html_path: str) -> dict:
    """Write ``report.html`` from ``validation.json`` alone (figures included); return the summary read."""
    with open(json_path) as f:
        summary = json.load(f)
    write_html(summary, report_figures(summary), html_path)
    return summary


def run_validation(out_dir: str, quick: bool = False, progress=None) -> dict:
    """Run the cases, the boundary lines and the coverage maps; write ``validation.json`` and,
    from it, ``report.html``. Return the summary as written to the JSON."""
    from .lines import LINE_SAMPLES, LINE_SAMPLES_FULL, LINES, boundary_line, line_summary

    os.makedirs(out_dir, exist_ok=True)
    cases = [c for c in default_cases() if c.quick or not quick]
    results = []
    steps = len(cases) + len(LINES) + 1  # then the report, printed as the last step done
    for i, case in enumerate(cases):
        if progress:
            progress(i, steps, case.name)
        results.append(run_case(case, out_dir))
    lines = {}
    for j, name in enumerate(LINES):
        if progress:
            progress(len(cases) + j, steps, f"boundary line {name}")
        lines[name] = line_summary(boundary_line(name, out_dir,
                                                 samples=LINE_SAMPLES if quick else LINE_SAMPLES_FULL[name]))
    if progress:
        progress(steps - 1, steps, "coverage maps")
    from .coverage_compare import compare_coverage
    from .sionna_runner import builtin_scene_path

    # the maps (wavepaths_db, sionna_db, difference_db) stay: the coverage figure is drawn from them
    coverage_summary = compare_coverage(builtin_scene_path("simple_street_canyon"), [-40.0, 0.0, 10.0],
                                        (0.0, 0.0, 1.5), (160.0, 80.0), 4.0 if quick else 2.0, 2)
    if progress:
        progress(steps, steps, "report")
    exact = exact_comparison(lines, EXACT_TOLERANCES)
    exact["known_disagreements"] = known_disagreement_verdicts(KNOWN_DISAGREEMENTS, exact)
    cases_passed = all(r["passed"] for r in results)
    coverage_passed = coverage_verdict(coverage_summary)
    summary = {
        "generated": time.strftime("%Y-%m-%d %H:%M:%S"),
        "quick": quick,
        "versions": _versions(),
        "tolerances": TOLERANCES,
        "cases": results,
        "lines": lines,
        "coverage": coverage_summary,
        "known_disagreements": KNOWN_DISAGREEMENTS,
        "exact_comparison": exact,
        "cases_passed": cases_passed,
        "coverage_passed": coverage_passed,
        "passed": cases_passed and exact["passed"] and coverage_passed,
    }
    json_path = os.path.join(out_dir, "validation.json")
    write_json(summary, json_path)
    return write_report(json_path, os.path.join(out_dir, "report.html"))
