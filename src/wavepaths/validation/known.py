"""Known disagreements between wavepaths and Sionna RT 2.2, each with its reason.

``exact_lines`` names the boundary lines of the report (``(line, field)``,
:mod:`wavepaths.validation.lines`) on which a disagreement shows against an exact solution:
the report computes from those lines' measured errors which engine matches the exact
solution (:func:`wavepaths.validation.verdict.known_disagreement_verdicts`).
``who_matches_exact`` is the documented answer (and the only one for the entries no line of
the report measures, each with the test that checks it).

``tests/validation/`` runs them as strict expected failures (``test_validation_report.py``)
or checks the exact solution behind them (``test_non_manifold_edges.py``,
``test_sionna_screen_collapse.py``): the day Sionna RT and wavepaths agree on one of them,
its test fails loudly and the entry must be removed.
"""

KNOWN_DISAGREEMENTS = [
    {
        "id": "hard-polarisation-coefficient",
        "exact_lines": [("half_plane", "hard"), ("wedge", "hard")],
        "exact_measure": "diffracted",
        "what": "Diffracted |a| for E perpendicular to the edge (hard) differs from Kouyoumjian-Pathak by up to "
                "tens of dB near the faces",
        "reason": "Sionna RT 2.2 combines the UTD terms as R0 (d1 - d4) + Rn (d2 - d3) in reflected bases; for a "
                  "perfect conductor its hard entry equals the soft coefficient (docs/sionna-diffraction.md). "
                  "wavepaths' textbook UTD reproduces the exact half-plane solution; compat='sionna' reproduces Sionna. "
                  "Judged on the diffracted paths alone (the exact field minus its geometrical optics): 46 dB off on "
                  "the half-plane line, and 38 dB on the wedge line where Sionna finds its diffracted paths (1e7 "
                  "samples, the full report), as compat's.",
        "who_matches_exact": "wavepaths (UTD)",
    },
    {
        "id": "reflection-boundary-jump",
        "exact_lines": [("half_plane", "soft"), ("wedge", "soft")],
        "exact_measure": "diffracted",
        "what": "Sionna's total field jumps by about twice the incident amplitude across every reflection boundary",
        "reason": "The 0-face reflection-boundary term d4 enters with -R0 instead of +R0, so the diffracted field's "
                  "half-jump adds to the reflected field's jump instead of cancelling it "
                  "(docs/sionna-diffraction.md §4). Judged on the diffracted paths alone: next to a reflection "
                  "boundary Sionna's diffracted field is off by about the incident amplitude (0.93 on the half-plane "
                  "line, 1.14 on the wedge line with 1e7 samples), as compat's.",
        "who_matches_exact": "wavepaths (UTD)",
    },
    {
        "id": "sionna-dr-depends-on-max-depth",
        "what": "Sionna's coefficient of a diffraction-then-reflection (D-R) path changes with max_depth: 4.5 to 8 dB "
                "weaker at max_depth=3 than at max_depth=2 for the same geometry",
        "reason": "Measured on simple_street_canyon (validation case and tests/validation): at max_depth=2 Sionna's "
                  "D-R paths equal wavepaths' compat values to 1e-3 dB; at max_depth=3 the same paths drop while "
                  "D, R-D, R-D-R and D-R-R paths do not. A path's field cannot depend on the search depth; "
                  "wavepaths' value does not. Mechanism (etoile_crop, 2 receivers, every D-R path to 0.01 dB): "
                  "Sionna's FieldCalculator._diffraction_compute_s_s_prime adds the segment to the vertex stored "
                  "in the slot after the last interaction (interaction type NONE, a leftover point) before it "
                  "stops, then the segment from that point to the receiver, so s, the distance after the "
                  "diffraction, includes a detour that is not on the path; the spreading "
                  "1/sqrt(s s' (s + s')) with that s gives Sionna's max_depth=3 value. With max_depth=2 there is "
                  "no such slot. KP's s for a diffracted ray reflected by a plane is the unfolded length, as "
                  "wavepaths uses.",
        "who_matches_exact": "wavepaths (consistent); Sionna at max_depth=2",
    },
    {
        "id": "diffraction-between-objects",
        "exact_lines": [("wedge_awning", "soft"), ("wedge_awning", "hard")],
        "exact_measure": "diffracted",
        "what": "Edges shared by two objects (a box standing on a ground plane, blocks touching, an awning hinged "
                "on a roof edge) diffract in wavepaths with the free-space sector of all their faces; Sionna "
                "diffracts there with one object's wedge, or not at all",
        "reason": "Sionna RT 2.2 finds wedges from opposite half-edges inside one mesh; wavepaths builds one "
                  "dihedron per edge from every face of every object on it (seed §3.2). The wedge_awning line (a "
                  "metal awning, another object, hinged on the wedge's edge; both lit) judges the diffracted paths "
                  "alone against the exact field of the sector between the lit face and the awning (n = 7/6): "
                  "wavepaths' are within 0.005 dB of it; Sionna's, at 88 of the 103 receivers, are 13 dB (hard) "
                  "and 51 dB (soft) off, and differ from compat='sionna' on wavepaths' sector too, so Sionna "
                  "diffracts with another wedge there. On the three_face_edge case its 10 matched paths on that "
                  "edge lie 20-29 dB from wavepaths' (exempted from the path tolerance). Sionna's total field "
                  "also misses reflections with 1e6 samples (58 of 73 on the line; all with 1e7).",
        "who_matches_exact": "wavepaths (the sector of all the edge's faces)",
    },
    {
        "id": "non-manifold-edge-wedge",
        "what": "On an edge where three or more faces of one mesh meet (two blocks of one building sharing a party "
                "wall, their facades continuing each other), Sionna diffracts with one block's right-angled corner "
                "(n = 1.5); wavepaths with the edge's free-space sector, nearly flat (n = 1.0005 on etoile_crop), "
                "whose coefficient is tens of dB smaller",
        "reason": "Sionna RT 2.2 builds its wedge from one pair of the mesh's half-edges (Mitsuba's "
                  "opposite_dedge): two of the faces, ignoring the other block's solid. On etoile_crop (benchmark 2) "
                  "25 matched R-D and R-D-R paths differ by 36-84 dB; wavepaths' compat model evaluated on Sionna's "
                  "block wedge reproduces Sionna's |a| to 0.02 dB, and the exact PEC wedge solution for the true "
                  "sector equals wavepaths' coefficient to 0.1 dB and lies 30-100 dB below the right-angled "
                  "wedge's (tests/validation/test_non_manifold_edges.py; docs/sionna-diffraction.md §6).",
        "who_matches_exact": "wavepaths (the free-space sector of all the faces)",
    },
    {
        "id": "sionna-free-edge-collapses-to-flat",
        "what": "On some free edges (a screen, or the top edge of a wall whose roof is another object) Sionna's "
                "diffraction coefficient is zero to float32 precision (|a| 60 to 180 dB below the half-plane's)",
        "reason": "Sionna RT 2.2's wedge_geometry orients the wedge's two normals by the side on which the other "
                  "face's centroid lies, with a float32 margin of 6e-6 m; on a free edge the other face is the "
                  "same triangle (nn = -n0), whose centroid lies in its own plane, so float32 rounding of "
                  "vertices tens of metres from the origin can flip one normal: n0 = nn, interior angle pi "
                  "(Sionna's own wedge_geometry returns 180 deg for etoile's element_015 wall top edge, 0 deg for "
                  "the roof edge beside it), n = 1, and the UTD terms cancel. Sommerfeld's exact half-plane "
                  "solution is not zero there; wavepaths' coefficient equals it "
                  "(tests/validation/test_sionna_screen_collapse.py). On etoile_crop 31 matched paths (all on "
                  "wall tops under a roof of another object, so also 'diffraction-between-objects').",
        "who_matches_exact": "wavepaths (UTD = Sommerfeld for the half-plane)",
    },
    {
        "id": "sionna-los-skips-last-segment-fraction",
        "exact_lines": [("half_plane", "soft"), ("half_plane", "hard")],
        "what": "At phi = 359 deg on the half_plane line (rho = 1 m, the receiver 1.7 cm behind the screen's far "
                "face, deep shadow) Sionna RT returns an unobstructed line-of-sight path, |u| = 1 (0 dB) in both "
                "fields, where the exact field is -71 dB (soft) and -25 dB (hard)",
        "reason": "Sionna RT 2.2 tests line of sight with a ray shortened by a relative 100 float32 epsilons "
                  "(maxt = length (1 - 5.96e-6)), so an obstacle within 5.96e-6 of the path's length before the "
                  "receiver is not seen: 6 cm for this line's transmitter 10 km away; the screen crosses the "
                  "line 2.0 cm before the receiver. Mitsuba's ray test over the whole length reports it "
                  "occluded, and with the transmitter 100 m away Sionna finds no such path "
                  "(tests/validation/test_validation_report.py). Without it Sionna's field there equals "
                  "wavepaths compat='sionna'; wavepaths' search finds no line of sight.",
        "who_matches_exact": "wavepaths (UTD)",
    },
    {
        "id": "sionna-near-coplanar-mirror-substitution",
        "what": "A Sionna diffracted path with a reflection whose diffraction point was placed with one mirror's "
                "plane and whose reflection point lies on another, nearly coplanar face (a neighbouring facade): "
                "on etoile_crop (benchmark 2) one D-R path at receiver 80, its points 12-14 cm from the path "
                "wavepaths finds with the same edge and the recorded mirror, so the 2 cm matcher leaves it "
                "unmatched",
        "reason": "Sionna RT 2.2's image method places the diffraction point in closed form from the images in the "
                  "mirror its candidate ray hit (here element_233's facade). Tracing back from the receiver it "
                  "accepts another triangle hit whose image lies within 1 cm of the first (element_022's facade, "
                  "1.13 mrad from it, its plane 2 mm away at the reflection point), records that triangle and its "
                  "hit point, and does not place the diffraction point again. The point then obeys Keller's law "
                  "for the first facade (residual 6.4e-8, rays aimed at the receiver's image) and not for the "
                  "recorded one (1.65e-3, where Sionna's float32 points give at most 2.6e-6 on the run's other "
                  "diffracted paths); the recorded reflection breaks the law of reflection by 1.7e-3. wavepaths' "
                  "path on the recorded facade obeys both to 2e-16. The report names such a path by that test "
                  "(validation.disagreements._sionna_mirror_substitution), which "
                  "tests/validation/test_unmatched_reasons.py checks on a made-up path of the same kind; benchmark 2 "
                  "counts the Sionna paths it names on etoile_crop (1 in the twenty-seventh session's run).",
        "who_matches_exact": "wavepaths (Keller's law and the law of reflection on the recorded mirror)",
    },
    {
        "id": "sampling-misses",
        "what": "Some valid paths (higher-order reflections, diffraction with reflections) are absent from Sionna's "
                "output",
        "reason": "Sionna samples candidate paths by shooting rays and caps them per source "
                  "(max_num_paths_per_src); wavepaths enumerates exhaustively (tests/search/test_completeness.py).",
        "who_matches_exact": "wavepaths (complete)",
    },
]
