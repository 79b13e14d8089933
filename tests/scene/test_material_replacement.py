"""Replacing a scene's materials by name (:func:`wavepaths.scene.with_materials`,
``--replace-material``): for frequencies outside the ITU-R P.2040 materials' range, or to try
another material, without editing the scene file."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.constants import epsilon_0

from wavepaths import TraceOptions, WavepathsError, load_scene, trace
from wavepaths.em.materials import Material
from wavepaths.fields import FieldConfig, compute_fields
from wavepaths.scene import with_materials

from ..conftest import strict_json

WAVEPATHS = os.path.join(os.path.dirname(sys.executable), "wavepaths")
TX, RX = [-60.0, 0.5, 10.0], [-20.0, 0.5, 2.0]  # in the street, the ground reflection at 10 : 2
EPS_R, SIGMA, F = 15.0, 0.035, 0.9e9  # a ground at 900 MHz, below P.2040's 1 GHz


def test_the_replaced_ground_reflects_by_fresnels_law_at_a_frequency_itu_does_not_cover():
    """At 900 MHz the street canyon's ITU ground is refused; replaced by eps_r = 15,
    sigma = 0.035 S/m, the ground reflection over the line of sight is |Gamma_TM| d_los / d_r
    (half-space, vertical polarisation in the plane of incidence: TM), Gamma_TM from the
    textbook formula, to 1e-9."""
    scene = load_scene("street_canyon")
    cfg = FieldConfig(F, reflection_model="half_space")
    with pytest.raises(WavepathsError, match="medium_dry_ground"):
        cfg.check_materials(scene)
    only_ground = with_materials(scene, {"medium_dry_ground": Material("ground", "custom", a=EPS_R, c=SIGMA)})
    assert only_ground.materials[1] == scene.materials[1]  # the walls' concrete is unchanged...
    with pytest.raises(WavepathsError, match="'concrete'"):
        cfg.check_materials(only_ground)  # ...and is not valid at 900 MHz either
    ground = with_materials(only_ground, {"concrete": Material("walls", "custom", a=5.24, c=0.0123)})
    cfg.check_materials(ground)
    paths = trace(ground, [TX], [RX], TraceOptions(max_reflections=1, diffraction=False))
    res = compute_fields(ground, paths, cfg)
    names = paths.objects(ground)
    los = int(np.nonzero(paths.depth == 0)[0][0])
    refl = int(np.nonzero((paths.depth == 1) & (names[:, 0] == ground.object_names.index("ground")))[0][0])
    d_los, d_r = paths.lengths[los], paths.lengths[refl]
    cos_t = 12.0 / d_r  # heights 10 + 2 over the unfolded length
    eta = EPS_R - 1j * SIGMA / (2 * np.pi * F * epsilon_0)
    root = np.sqrt(eta - (1 - cos_t**2))
    gamma_tm = (eta * cos_t - root) / (eta * cos_t + root)
    ratio = abs(res.a[refl]) / abs(res.a[los])
    assert ratio == pytest.approx(abs(gamma_tm) * d_los / d_r, rel=1e-9)
    # the geometry and which triangles share a material are unchanged
    np.testing.assert_array_equal(ground.vertices, scene.vertices)
    np.testing.assert_array_equal(ground.triangle_material, scene.triangle_material)


def test_a_named_replacement_keeps_the_slab_thickness_and_bad_names_are_refused():
    scene = load_scene("street_canyon")
    walls = scene.materials[1]
    metal = with_materials(scene, {walls.name: "metal"}).materials[1]
    assert metal.name == "metal" and metal.thickness_m == walls.thickness_m
    own = with_materials(scene, {walls.name: Material("thin", "custom", a=4.0, thickness_m=0.02)}).materials[1]
    assert own.thickness_m == 0.02
    with pytest.raises(WavepathsError, match=r"no materials of the scene.*medium_dry_ground"):
        with_materials(scene, {"glass": "pec"})
    with pytest.raises(WavepathsError, match="unknown material name 'steel'"):
        with_materials(scene, {walls.name: "steel"})


def run(*args):
    return subprocess.run([WAVEPATHS, "paths", *map(str, args)], capture_output=True, text=True, timeout=300)


def test_cli_replace_material_gives_the_apis_fields():
    """``--replace-material NAME=EPS_R,SIGMA`` (and ``NAME=name``) gives the path gains of
    :func:`with_materials` with the same materials; its errors name the flag."""
    common = ["street_canyon", "--tx", *TX, "--rx", *RX, "--max-reflections", 1, "--frequency", F, "--json"]
    refused = run(*common)
    assert refused.returncode == 2 and "--replace-material medium_dry_ground=EPS_R,SIGMA" in refused.stderr
    r = run(*common, "--replace-material", f"medium_dry_ground={EPS_R},{SIGMA}", "--replace-material", "concrete=pec")
    assert r.returncode == 0, r.stderr
    got = strict_json(r.stdout)["receivers"][0]["path_gain_db"]
    scene = load_scene("street_canyon")
    api = with_materials(scene, {"medium_dry_ground": Material("medium_dry_ground", "custom", a=EPS_R, c=SIGMA),
                                 "concrete": "pec"})
    paths = trace(api, [TX], [RX], TraceOptions(max_reflections=1))
    assert got == pytest.approx(float(compute_fields(api, paths, FieldConfig(F)).path_gain_db(True)[0, 0]), abs=1e-9)
    for bad, message in (("glass=pec", "--replace-material names ['glass']"),
                         ("concrete", "must be NAME=VALUE"),
                         ("concrete=0.5,1", "relative permittivity"),
                         ("concrete=a,b", "must be two numbers")):
        r = run(*common[:-3], "--replace-material", bad)
        assert r.returncode == 2 and message in r.stderr and "Traceback" not in r.stderr, (bad, r.stderr)
