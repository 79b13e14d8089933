"""Known disagreements between wavepaths and Sionna RT 2.2, each with its reason.

``tests/validation/test_known_disagreements.py`` runs each one as a strict expected
failure: the day Sionna RT and wavepaths agree on one of them, that test fails loudly and
the entry must be removed.
"""

KNOWN_DISAGREEMENTS = [
    {
        "id": "hard-polarisation-coefficient",
        "what": "Diffracted |a| for E perpendicular to the edge (hard) differs from Kouyoumjian-Pathak by up to "
                "tens of dB near the faces",
        "reason": "Sionna RT 2.2 combines the UTD terms as R0 (d1 - d4) + Rn (d2 - d3) in reflected bases; for a "
                  "perfect conductor its hard entry equals the soft coefficient (docs/sionna-diffraction.md). "
                  "wavepaths' textbook UTD reproduces the exact half-plane solution; compat='sionna' reproduces Sionna.",
        "who_matches_exact": "wavepaths (UTD)",
    },
    {
        "id": "reflection-boundary-jump",
        "what": "Sionna's total field jumps by about twice the incident amplitude across every reflection boundary",
        "reason": "The 0-face reflection-boundary term d4 enters with -R0 instead of +R0, so the diffracted field's "
                  "half-jump adds to the reflected field's jump instead of cancelling it "
                  "(docs/sionna-diffraction.md §4).",
        "who_matches_exact": "wavepaths (UTD)",
    },
    {
        "id": "both-faces-lit-face-choice",
        "what": "On a wedge whose two faces are both lit, Sionna's diffracted field depends on which face its "
                "sampled ray hit",
        "reason": "Sionna takes the face its candidate ray hit as the 0-face, and its combination "
                  "R0 (d1 - d4) + Rn (d2 - d3) is not symmetric under exchanging the faces; compat='sionna' takes the "
                  "face with phi' < pi and so reproduces Sionna only where one face is lit.",
        "who_matches_exact": "wavepaths (UTD)",
    },
    {
        "id": "sionna-dr-depends-on-max-depth",
        "what": "Sionna's coefficient of a diffraction-then-reflection (D-R) path changes with max_depth: 4.5 to 8 dB "
                "weaker at max_depth=3 than at max_depth=2 for the same geometry",
        "reason": "Measured on simple_street_canyon (validation case and tests/validation): at max_depth=2 Sionna's "
                  "D-R paths equal wavepaths' compat values to 1e-3 dB; at max_depth=3 the same paths drop while "
                  "D, R-D, R-D-R and D-R-R paths do not. A path's field cannot depend on the search depth; "
                  "wavepaths' value does not.",
        "who_matches_exact": "wavepaths (consistent); Sionna at max_depth=2",
    },
    {
        "id": "diffraction-between-objects",
        "what": "Edges shared by two objects (a box standing on a ground plane, blocks touching) diffract in "
                "wavepaths, not in Sionna",
        "reason": "Sionna RT 2.2 finds wedges from opposite half-edges inside one mesh; wavepaths builds one "
                  "dihedron per edge from every face of every object on it (seed §3.2).",
        "who_matches_exact": "topology rule (no exact solution)",
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
