"""The exact solutions as arbiter: which engine matches them, and the report's overall verdict.

Sionna RT is a peer, the exact solutions (Sommerfeld's half-plane, the wedge eigenfunction
series; :mod:`wavepaths.validation.lines`) are the arbiter. On each boundary line and
polarisation an engine *matches the exact solution* when its total field stays within
:data:`EXACT_TOLERANCES` of it. wavepaths' textbook UTD must match on every line, or the
report fails; Sionna RT is measured the same way and reported, not held (its departures are
the documented disagreements of :mod:`wavepaths.validation.known`).

Tolerances, and why (the line: a point source ``lines.S_PRIME`` = 10 km away standing in for a
plane wave, receivers at k rho ~ 73 from the edge, 3.5 GHz):

* ``exact_max_db`` = 0.5 dB: largest |u| difference where the exact field is lit
  (|u| > 0.05, :func:`~wavepaths.validation.lines.line_errors`). UTD is asymptotic in
  1/(k rho) and the source's wave is spherical (curvature error k rho^2 / 2 s' ~ 4e-3); both
  are largest next to the shadow and reflection boundaries, where wavepaths' UTD measures
  0.05 to 0.33 dB. The same bound as a diffracted path's |a| in compat mode. Sionna RT
  measures 6 to 36 dB on its documented cases.
* ``exact_max_complex_error`` = 0.02: largest |u - u_exact| (incident field at the edge = 1),
  which also sees phase errors; wavepaths' UTD measures 0.005 to 0.007.

The same tolerances hold each engine's diffracted paths alone against the exact field minus its
geometrical optics (:func:`~wavepaths.validation.lines.diffracted_errors`, at the receivers
where the engine has a diffracted path): that measure isolates the diffraction coefficient from
a missing reflection or a delay floor. wavepaths' UTD measures 0.0008 to 0.0045 dB and at most
3.4e-4 there on the three lines (the spherical wave's curvature is in the geometrical-optics terms). A known
disagreement about a coefficient is judged on it (``"exact_measure": "diffracted"``).
"""

from __future__ import annotations

import math

EXACT_TOLERANCES = {"exact_max_db": 0.5, "exact_max_complex_error": 0.02}

# what a line measures against its exact solution: the total field, and each engine's diffracted
# paths alone against the exact field minus its geometrical optics (lines.diffracted_errors),
# which isolates the diffraction coefficient from missing reflections and delay floors
MEASURES = {"errors": "total field", "diffracted_errors": "diffracted field"}

# the engine held to the exact solutions, and the one measured beside it
HELD_ENGINE = "wavepaths UTD"
PEER_ENGINE = "Sionna RT"
ENGINES = (HELD_ENGINE, PEER_ENGINE)
FIELDS = ("soft", "hard")


def _within(err: dict | None, tolerances: dict) -> bool:
    """Whether one engine's line errors are within the tolerances (a missing or non-finite error is not)."""
    if err is None:
        return False
    values = (err.get("max_db"), err.get("max_complex_error"))
    if any(v is None or not math.isfinite(v) for v in values):
        return False
    return values[0] <= tolerances["exact_max_db"] and values[1] <= tolerances["exact_max_complex_error"]


def _who(within: dict) -> str:
    """The engines that match, in words: one engine's name, ``"both"`` or ``"neither"``."""
    ok = [e for e in ENGINES if within.get(e)]
    if len(ok) == len(ENGINES):
        return "both"
    return ok[0] if ok else "neither"


def exact_comparison(lines: dict, tolerances: dict = EXACT_TOLERANCES) -> dict:
    """Each engine against the exact solution on every boundary line, and the verdict.

    Parameters
    ----------
    lines : dict
        ``summary["lines"]``: line name -> entry whose ``errors`` are
        :func:`~wavepaths.validation.lines.line_errors` (keys ``"<engine> (soft|hard)"``).
    tolerances : dict
        ``exact_max_db`` [dB] and ``exact_max_complex_error`` (see the module docstring).

    Returns
    -------
    dict
        ``lines``: name -> field (``"soft"``/``"hard"``) -> ``{"engines": {engine: {"max_db",
        "max_complex_error", "within_tolerance"}}, "matches_exact": engine | "both" | "neither"}``
        for the total field, and ``"diffracted_engines"`` (each also with ``"receivers"``, those
        where the engine has a diffracted path) and ``"diffracted_matches_exact"`` for the
        diffracted field when the line measured it (:data:`MEASURES`);
        ``violations``: list of str (wavepaths' UTD outside the tolerances on either measure, or
        not measured);
        ``passed``: bool, no violation and at least one line.
    """
    out_lines, violations = {}, []
    for name, entry in lines.items():
        out_lines[name] = {}
        for field in FIELDS:
            out_lines[name][field] = {}
            for measure, what in MEASURES.items():
                errors = entry.get(measure)
                if errors is None:  # a summary written before the diffracted field was measured
                    continue
                engines = {}
                for engine in ENGINES:
                    err = errors.get(f"{engine} ({field})")
                    if err is None:
                        continue
                    engines[engine] = {"max_db": err["max_db"], "max_complex_error": err["max_complex_error"],
                                       "within_tolerance": _within(err, tolerances)}
                    if "receivers" in err:
                        engines[engine]["receivers"] = err["receivers"]
                held = engines.get(HELD_ENGINE)
                if held is None:
                    violations.append(f"{name} {field}: {HELD_ENGINE}'s {what} not measured against the exact solution")
                elif not held["within_tolerance"]:
                    violations.append(f"{name} {field}: {HELD_ENGINE}'s {what}: max |u| error {_num(held['max_db'])} dB, "
                                      f"complex {_num(held['max_complex_error'])} (tolerance "
                                      f"{tolerances['exact_max_db']} dB, {tolerances['exact_max_complex_error']})")
                key = "" if measure == "errors" else "diffracted_"
                out_lines[name][field][key + "engines"] = engines
                out_lines[name][field][key + "matches_exact"] = _who({e: v["within_tolerance"] for e, v in engines.items()})
    if not lines:
        violations.append("no boundary line compared with an exact solution")
    return {"tolerances": dict(tolerances), "held_engine": HELD_ENGINE, "lines": out_lines,
            "violations": violations, "passed": not violations}


def _num(x) -> str:
    return "n/a" if x is None else format(x, ".3g")


def _engine_detail(engine: str, v: dict) -> str:
    """``"Sionna RT 46 dB, 0.92 complex"`` (the largest |u| error and |u - u_exact|), or
    ``"Sionna RT no diffracted path"`` when it has none to judge."""
    if v.get("receivers") == 0:
        return f"{engine} no diffracted path"
    return f"{engine} {_num(v['max_db'])} dB, {_num(v['max_complex_error'])} complex"


def known_disagreement_verdicts(known: list, exact: dict) -> dict:
    """Which engine matches the exact solution on each known disagreement, from the measured errors.

    Parameters
    ----------
    known : list of dict
        :data:`~wavepaths.validation.known.KNOWN_DISAGREEMENTS`; an entry's ``exact_lines``
        lists the ``(line, field)`` pairs of this report on which it shows, and its
        ``exact_measure`` (``"total"``, the default, or ``"diffracted"``) which field is judged.
    exact : dict
        :func:`exact_comparison`'s result.

    Returns
    -------
    dict
        id -> ``{"measured_on": [[line, field], ...], "measure": "total" | "diffracted",
        "matches_exact": engine | "both" | "neither" | None, "detail": str}`` (no ``"measure"``
        when nothing was measured). An engine matches when it is within the tolerances on every
        listed pair (on the diffracted field, only where it has a diffracted path: none is not a match); ``None`` when no listed pair was measured (no exact solution in this
        report: the entry's documented ``who_matches_exact`` stands, with its test).
    """
    out = {}
    for k in known:
        pairs = [(line, field) for line, field in k.get("exact_lines", ())
                 if field in exact["lines"].get(line, {})]
        if not pairs:
            out[k["id"]] = {"measured_on": [], "matches_exact": None,
                            "detail": "no exact-solution line in this report"}
            continue
        measure = k.get("exact_measure", "total")
        key = "diffracted_engines" if measure == "diffracted" else "engines"
        within = {e: True for e in ENGINES}
        details = []
        for line, field in pairs:
            engines = exact["lines"][line][field].get(key)
            if engines is None:  # a summary without that measure: judged on the total field
                measure, engines = "total", exact["lines"][line][field]["engines"]
            for e in ENGINES:
                within[e] &= bool(engines.get(e, {}).get("within_tolerance", False))
            details.append(f"{line} {field}: " + ", ".join(_engine_detail(e, engines[e]) for e in ENGINES if e in engines))
        out[k["id"]] = {"measured_on": [list(p) for p in pairs], "measure": measure,
                        "matches_exact": _who(within),
                        "detail": f"{measure} field: " + "; ".join(details)}
    return out
