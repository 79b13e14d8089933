"""The ``wavepaths`` command line: a thin layer over the Python API.

Every subcommand turns a :class:`~wavepaths.errors.WavepathsError` into one line on
standard error and exit status 2, without a traceback. The JSON it prints is strict JSON:
a number that is not finite (``-inf`` dB where no path arrives, NaN) is written ``null``
(:func:`json_text`).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
import warnings
from typing import Callable, Sequence

import numpy as np

from .errors import WavepathsError


def json_ready(value):
    """``value`` with every non-finite float (NaN, ``inf``, ``-inf``) replaced by ``None``,
    numpy scalars and arrays turned into Python numbers and lists, tuples into lists."""
    if isinstance(value, dict):
        return {k: json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_ready(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


def json_text(value, indent: int | None = 1) -> str:
    """Strict JSON for ``value``: non-finite numbers become ``null`` (:func:`json_ready`);
    ``NaN``, ``Infinity`` and ``-Infinity``, which JSON does not have, are never written."""
    return json.dumps(json_ready(value), indent=indent, allow_nan=False)


SCENE_HELP = "built-in scene name or scene file (XML, OBJ, PLY, OFF, STL, glTF/GLB)"


def add_scene_arguments(p: argparse.ArgumentParser) -> None:
    """The positional ``scene``, ``--up-axis`` and ``--material`` (:func:`wavepaths.scene.load_scene`'s
    ``up_axis`` and ``material``)."""
    p.add_argument("scene", help=SCENE_HELP)
    p.add_argument("--up-axis", choices=["auto", "y", "z"], default="auto",
                   help="the up axis of a mesh file: auto (default: +Y for glTF/GLB, rotated to +Z; +Z for the "
                        "others), y (rotate any mesh file from +Y up), z (keep the file's coordinates)")
    p.add_argument("--material", metavar="NAME",
                   help="material of a mesh file's triangles that name no known material (OBJ usemtl, glTF "
                        "materials named after ITU-R P.2040 materials are used): pec (default), absorber or an "
                        "ITU-R P.2040 name such as concrete")
    p.add_argument("--replace-material", metavar="NAME=VALUE", action="append",
                   help="replace the scene's material NAME (see `wavepaths info`) by VALUE: pec, absorber, an "
                        "ITU-R P.2040 name, or EPS_R,SIGMA (relative permittivity, conductivity [S/m], at every "
                        "frequency), e.g. for a frequency outside the ITU materials' range; repeat for several")


def _scene(args):
    from .scene import load_scene, with_materials

    scene = load_scene(args.scene, up_axis=getattr(args, "up_axis", "auto"), material=getattr(args, "material", None))
    replace = getattr(args, "replace_material", None)
    return with_materials(scene, material_replacements(replace, scene)) if replace else scene


def material_replacements(items: list[str], scene) -> dict:
    """The ``--replace-material NAME=VALUE`` flags as :func:`wavepaths.scene.with_materials`'
    mapping: ``VALUE`` a material name (``pec``, ``absorber``, an ITU-R P.2040 name) or
    ``EPS_R,SIGMA``, a frequency-independent material of relative permittivity ``EPS_R`` and
    conductivity ``SIGMA`` [S/m], with the slab thickness of the material it replaces."""
    from .em.materials import DEFAULT_THICKNESS_M, Material

    thickness = {m.name: m.thickness_m for m in scene.materials}
    out: dict = {}
    for item in items:
        name, sep, value = (x.strip() for x in item.partition("="))
        if not sep or not name or not value:
            raise WavepathsError(f"--replace-material must be NAME=VALUE (VALUE a material name or EPS_R,SIGMA), "
                                 f"got {item!r}")
        if name in out:
            raise WavepathsError(f"--replace-material gives material {name!r} twice")
        parts = value.split(",")
        if len(parts) != 2:
            out[name] = value  # a name: with_materials checks it
            continue
        try:
            eps_r, sigma = (float(x) for x in parts)
        except ValueError:
            raise WavepathsError(f"--replace-material {item!r}: EPS_R,SIGMA must be two numbers") from None
        try:
            out[name] = Material(name, "custom", a=eps_r, c=sigma, thickness_m=thickness.get(name, DEFAULT_THICKNESS_M))
        except WavepathsError as exc:
            raise WavepathsError(f"--replace-material {item!r}: {exc}") from None
    return out


def _cmd_info(args) -> int:
    scene = _scene(args)
    info = scene.summary()
    if args.json:
        print(json_text(info, indent=2))
        return 0
    print(f"scene      {info['source']}")
    print(f"triangles  {info['triangles']}")
    names = info["object_names"]
    shown = ", ".join(names[:INFO_NAMES]) + (f", ... and {len(names) - INFO_NAMES} more (--json lists them all)"
                                             if len(names) > INFO_NAMES else "")
    print(f"objects    {info['objects']} ({shown})")
    print(f"materials  {info['materials']} ({', '.join(info['material_names'])})")
    print(f"polygons   {info['polygons']}")
    by = info["dihedra_by_face_count"]
    print(f"dihedra    {info['dihedra']} (1 face: {by['1']}, 2 faces: {by['2']}, 3+ faces: {by['3+']}; "
          f"{info['diffracting_dihedra']} can diffract)")
    print(f"flat edges {info['skipped_flat_edges']} skipped")
    lo, hi = info["bounds"]
    print(f"bounds     [{lo[0]:.3f}, {lo[1]:.3f}, {lo[2]:.3f}] .. [{hi[0]:.3f}, {hi[1]:.3f}, {hi[2]:.3f}] m")
    return 0


def _warn_ignored_flags(args) -> None:
    """Say so when a trace flag given on the command line has no effect with the others (a
    review found them all accepted in silence, and a search of nothing reported as a result)."""
    from .scene.model import WavepathsWarning

    ignored = []
    if args.no_diffraction:
        for flag, given in (("--diffraction-reflections", args.diffraction_reflections != 1),
                            ("--no-lit-region", args.no_lit_region),
                            ("--no-free-edges", getattr(args, "no_free_edges", False)),
                            ("--tolerance-db", getattr(args, "tolerance_db", None) is not None),
                            ("--diffraction-candidates", getattr(args, "diffraction_candidates", "exhaustive")
                             != "exhaustive")):
            if given:
                ignored.append(f"{flag} (with --no-diffraction)")
    if getattr(args, "launch_fan", 256) != 256 and getattr(args, "diffraction_candidates", "exhaustive") != "launched":
        ignored.append("--launch-fan (without --diffraction-candidates launched)")
    if (getattr(args, "launch_rays", 1 << 21) != 1 << 21
            and getattr(args, "reflection_candidates", "exhaustive") != "launched"):
        ignored.append("--launch-rays (without --reflection-candidates launched)")
    if ignored:
        warnings.warn("ignored: " + "; ".join(ignored), WavepathsWarning, stacklevel=2)
    if args.no_los and args.no_diffraction and args.max_reflections == 0:
        warnings.warn("--no-los, --no-diffraction and --max-reflections 0 leave nothing to search: no path will "
                      "be found", WavepathsWarning, stacklevel=2)


INFO_NAMES = 12  # object names `info` prints (a city has hundreds: --json has them all)


def _trace_options(args):
    from .search import TraceOptions

    _warn_ignored_flags(args)
    return TraceOptions(
        los=not args.no_los,
        max_reflections=args.max_reflections,
        diffraction=not args.no_diffraction,
        diffraction_reflections=args.diffraction_reflections,
        lit_region=not args.no_lit_region,
        prune_db=args.prune_db,
        tolerance_db=getattr(args, "tolerance_db", None),
        diffraction_candidates=getattr(args, "diffraction_candidates", "exhaustive"),
        launch_fan=getattr(args, "launch_fan", 256),
        reflection_candidates=getattr(args, "reflection_candidates", "exhaustive"),
        launch_rays=getattr(args, "launch_rays", 1 << 21),
        free_edges=not getattr(args, "no_free_edges", False),
    )


def plural(n: int, word: str) -> str:
    """``n`` and ``word``, with an ``s`` unless ``n`` is 1: ``1 path``, ``3 paths``."""
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def _cmd_paths(args) -> int:
    from .search import trace

    scene = _scene(args)
    tx = np.array(args.tx, dtype=float).reshape(-1, 3)
    rx = np.array(args.rx, dtype=float).reshape(-1, 3)
    field_cfg = _field_config(args)  # checked before the search, with the scene's materials
    if field_cfg is not None:
        field_cfg.check_materials(scene)
    options = _trace_options(args)
    paths = trace(scene, tx, rx, options)
    result = None
    if field_cfg is not None:
        from .fields import compute_fields

        # the incident fields make the field strength independent of the receive antenna
        result = compute_fields(scene, paths, field_cfg)
    records = paths.records()
    objects = paths.objects(scene)
    (zd, ad), (za, aa) = paths.angles_of_departure, paths.angles_of_arrival
    for i, r in enumerate(records):
        d = int(paths.depth[i])
        r["objects"] = [scene.object_names[o] for o in objects[i, :d]]  # the object of each interaction
        r["departure_deg"] = {"zenith": float(np.degrees(zd[i])), "azimuth": float(np.degrees(ad[i]))}
        r["arrival_deg"] = {"zenith": float(np.degrees(za[i])), "azimuth": float(np.degrees(aa[i]))}
    if result is not None:
        a = result.a
        gain = result.gain_db
        for i, r in enumerate(records):
            r["a"] = [float(a[i].real), float(a[i].imag)]
            r["gain_db"] = float(gain[i])
    receivers = _receiver_entries(paths, result, rx, len(tx))
    if args.json:
        out = {"scene": scene.source, "tx": tx.tolist(), "rx": rx.tolist(), "paths": records, "receivers": receivers}
        if result is not None:
            out["frequency_hz"] = result.frequency_hz
        out.update(run_settings(options, field_cfg if result is not None else None))
        out["units"] = PATHS_JSON_UNITS
        print(json_text(out))
        return 0
    print(f"{plural(len(records), 'path')} in {scene.source}")
    header = f"{'tx':>3} {'rx':>3}  {'interactions':<34} {'length [m]':>11} {'delay [ns]':>11}"
    if result is not None:
        header += f" {'gain [dB]':>10}"
    print(header)
    for r in records:
        kinds = "-".join(f"{ {'reflection': 'R', 'diffraction': 'D'}[k]}({o})"
                         for k, o in zip(r["interactions"], r["objects"])) or "LOS"
        line = f"{r['tx']:>3} {r['rx']:>3}  {kinds:<34} {r['length_m']:>11.4f} {r['delay_s'] * 1e9:>11.4f}"
        if "gain_db" in r:
            line += f" {r['gain_db']:>10.2f}"
        print(line)
    if result is not None:
        _print_receiver_totals(receivers, len(tx), power_given=getattr(args, "tx_power_dbm", None) is not None)
    return 0


PATHS_JSON_UNITS = {
    "tx": "m", "rx": "m", "paths.vertices": "m", "paths.length_m": "m", "paths.delay_s": "s",
    "paths.departure_deg": "deg", "paths.arrival_deg": "deg",
    "paths.a": "[re, im] of the complex path coefficient, normalised like Sionna RT's Paths.a (unit transmit "
               "power, transmit port 0, receive port 0), without the carrier phase exp(-j 2 pi f tau): "
               "the receiver's coherent total is sum a exp(-j 2 pi frequency_hz delay_s)",
    "paths.gain_db": "dB (20 log10 |a|)",
    "receivers.position": "m", "receivers.path_gain_db": "dB", "receivers.path_gain_incoherent_db": "dB",
    "receivers.received_power_dbm": "dBm", "receivers.field_strength_v_m": "V/m",
    "receivers.field_strength_dbuv_m": "dBuV/m", "frequency_hz": "Hz", "tx_power_dbm": "dBm",
    "field_config.frequency_hz": "Hz", "field_config.tx_power_dbm": "dBm",
    "field_config.tx_antenna.orientation": "rad (about z, y, x; the command line's --tx-orientation is in deg)",
    "field_config.rx_antenna.orientation": "rad (about z, y, x; the command line's --rx-orientation is in deg)",
}
"""The unit of each number of ``paths --json``, written under its ``units`` key: the key
is the field's name, with its parents' names before a dot (``paths.a`` for the ``a`` of
each path)."""


def run_settings(options, field_cfg) -> dict:
    """The settings behind the numbers of ``paths --json``, named as ``coverage`` names them
    in its ``.npz`` (``tx_power_dbm``; ``trace_options`` and ``field_config`` as in its
    ``metadata``): the trace options, and with fields the transmit power [dBm] and the field
    configuration (frequency, model, antennas with their orientations [rad]).

    Parameters
    ----------
    options : TraceOptions
        The options the search ran with.
    field_cfg : FieldConfig or None
        The field settings, or None when no fields were computed.

    Returns
    -------
    dict
        ``trace_options``, and with fields ``tx_power_dbm`` and ``field_config``.
    """
    import dataclasses

    out: dict = {"trace_options": options.to_dict()}
    if field_cfg is not None:
        out["tx_power_dbm"] = field_cfg.tx_power_dbm
        out["field_config"] = dataclasses.asdict(field_cfg)
    return out


def _gain_text(totals: dict) -> str:
    """One receiver's path gain in words, coherent and power sum."""
    return (f"path gain {totals['path_gain_db']:.2f} dB (coherent), "
            f"{totals['path_gain_incoherent_db']:.2f} dB (power sum)")


def _power_text(totals: dict) -> str:
    """One receiver's received power [dBm] and the field strength [dBuV/m] an isotropic
    receiver sees, both from the coherent sum."""
    return (f"received power {totals['received_power_dbm']:.2f} dBm, field strength "
            f"{totals['field_strength_dbuv_m']:.2f} dBuV/m (coherent; isotropic receiver)")


def _print_receiver_totals(receivers: list[dict], num_tx: int, power_given: bool) -> None:
    """The per-receiver lines of ``paths``' text output; with ``--tx-power-dbm`` given, each
    gain line is followed by the received power and the field strength."""
    for e in receivers:
        if num_tx == 1:
            print(f"rx {e['rx']}: {_gain_text(e)}")
            if power_given:
                print(f"      {_power_text(e)}")
            continue
        best = "none (no path arrives)" if e["best_server"] is None else f"tx {e['best_server']}"
        print(f"rx {e['rx']}: best server {best}")
        for t in e["per_tx"]:
            print(f"  tx {t['tx']} -> rx {e['rx']}: {plural(t['num_paths'], 'path')}, {_gain_text(t)}")
            if power_given:
                print(f"      {_power_text(t)}")


def _receiver_entries(paths, result, rx: np.ndarray, num_tx: int) -> list[dict]:
    """The ``receivers`` of ``paths --json``: per receiver, its path count over all
    transmitters (``num_paths``), the totals of one transmitter (``totals_tx``: the best
    server, the one with the highest coherent path gain; transmitter 0 when no path
    arrives), ``best_server`` (``None`` when no path arrives) and ``per_tx``: one entry per
    transmitter with its ``num_paths`` and totals."""
    counts = np.zeros((num_tx, len(rx)), dtype=np.int64)
    np.add.at(counts, (paths.tx_index, paths.rx_index), 1)
    gain = result.path_gain(True) if result is not None else None
    entries = []
    for j in range(len(rx)):
        entry = {"rx": j, "position": rx[j].tolist(), "num_paths": int(counts[:, j].sum())}
        per_tx = [{"tx": i, "num_paths": int(counts[i, j])} for i in range(num_tx)]
        if result is not None:
            best = int(np.argmax(gain[:, j]))
            reached = bool(gain[best, j] > 0)
            entry["best_server"] = best if reached else None
            entry["totals_tx"] = best if reached else 0
            entry.update(result.receiver_summary(j, entry["totals_tx"]))
            for i, t in enumerate(per_tx):
                t.update(result.receiver_summary(j, i))
        entry["per_tx"] = per_tx
        entries.append(entry)
    return entries


def _field_config(args):
    """The field settings of ``paths`` (None when the fields module is not available)."""
    try:
        from .fields import FieldConfig
    except ImportError:
        return None
    return FieldConfig.from_cli(args)


def _add_trace_flags(p: argparse.ArgumentParser) -> None:
    p.add_argument("--max-reflections", type=int, default=2, help="highest order of specular paths (default 2)")
    p.add_argument("--no-diffraction", action="store_true", help="no edge diffraction")
    p.add_argument("--diffraction-reflections", type=int, default=1,
                   help="reflections combined with the diffraction, before and after (default 1)")
    p.add_argument("--no-lit-region", action="store_true", help="diffraction only in the incident shadow")
    p.add_argument("--no-free-edges", action="store_true",
                   help="no diffraction on free edges (edges of one face: a screen's or a finite ground's border); "
                        "Sionna RT without edge_diffraction skips these, and also the edges shared with another "
                        "object")
    p.add_argument("--no-los", action="store_true", help="leave out the line of sight")
    p.add_argument("--prune-db", type=float, default=None,
                   help="drop reflected paths whose length alone (|reflection coefficient| <= 1) puts them at "
                        "least this many dB below free space at the direct distance, for isotropic antennas "
                        "(with directive ones, add both peak gains in dBi); a path's actual coefficients are "
                        "not looked at (bound in TraceOptions.prune_db)")
    p.add_argument("--diffraction-candidates", choices=["exhaustive", "launched"], default="exhaustive",
                   help="diffracted candidates: every one no test rules out (default; complete), or those that "
                        "sampled Keller fans carry to each receiver (dense cities; may miss a path)")
    p.add_argument("--launch-fan", type=int, default=256,
                   help="with --diffraction-candidates launched: Keller-cone directions per turn (default 256)")
    p.add_argument("--reflection-candidates", choices=["exhaustive", "launched"], default="exhaustive",
                   help="specular candidates: every chain whose beam reaches the receiver (default; complete), or "
                        "those that transmitter rays carry to it (dense cities; may miss a path; one --tx only)")
    p.add_argument("--launch-rays", type=int, default=1 << 21,
                   help="with --reflection-candidates launched: rays from the transmitter (default 2097152)")


def _add_field_flags(p: argparse.ArgumentParser) -> None:
    p.add_argument("--frequency", type=float, default=3.5e9, help="carrier frequency [Hz] (default 3.5e9)")
    p.add_argument("--model", choices=["utd", "gtd"], default="utd",
                   help="diffraction coefficients: utd (Kouyoumjian-Pathak, the default) or gtd (Keller's, "
                        "which diverges on shadow and reflection boundaries: warned about)")
    p.add_argument("--compat", choices=["none", "sionna"], default="none",
                   help="'sionna' reproduces Sionna RT 2.2's diffraction combination")
    patterns = ["iso", "dipole", "hw_dipole", "tr38901"]
    p.add_argument("--polarization", choices=["V", "H"], default="V",
                   help="polarisation of both antennas (default V; dual-polarised antennas, VH and cross, "
                        "through the Python API's Antenna)")
    p.add_argument("--antenna", choices=patterns, default="iso",
                   help="pattern of the transmit AND the receive antenna (default iso); --tx-antenna and "
                        "--rx-antenna set one side")
    p.add_argument("--tx-antenna", choices=patterns, help="transmit antenna pattern (default: --antenna)")
    p.add_argument("--rx-antenna", choices=patterns, help="receive antenna pattern (default: --antenna)")
    for side in ("tx", "rx"):
        p.add_argument(f"--{side}-orientation", nargs=3, type=float, default=[0.0, 0.0, 0.0],
                       metavar=("YAW", "PITCH", "ROLL"),
                       help=f"{'transmit' if side == 'tx' else 'receive'} antenna orientation [deg] about z, y, x "
                            "(TR 38.901 7.1.3, as Sionna RT's; default 0 0 0: boresight along +x)")
    p.add_argument("--tx-power-dbm", type=float, default=None,
                   help="transmit power [dBm] (default 0); when it is given, the text of `paths` also shows "
                        "the received power [dBm] and the field strength [dBuV/m]")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="wavepaths", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("info", help="describe a scene: triangles, polygons, dihedra")
    add_scene_arguments(p)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_cmd_info)

    p = sub.add_parser("paths", help="list the propagation paths between transmitters and receivers")
    add_scene_arguments(p)
    p.add_argument("--tx", nargs=3, type=float, action="append", required=True, metavar=("X", "Y", "Z"),
                   help="transmitter position [m]; repeat for several")
    p.add_argument("--rx", nargs=3, type=float, action="append", required=True, metavar=("X", "Y", "Z"),
                   help="receiver position [m]; repeat for several")
    _add_trace_flags(p)
    _add_field_flags(p)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_cmd_paths)

    for _name, hook in _extra_commands():
        hook(sub)
    _accept_negative_numbers(parser)
    return parser


# every spelling of a negative number, exponents included: argparse's own pattern takes -1e-6
# and -3e9 for options, so that `--rx 20 -1e-6 1.5` could not be written at all
_NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


def _accept_negative_numbers(parser: argparse.ArgumentParser) -> None:
    """Let ``parser`` and its subcommands' parsers read ``-1e-6`` as a value, not an option."""
    parser._negative_number_matcher = _NEGATIVE_NUMBER  # argparse's only hook for this
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in action.choices.values():
                _accept_negative_numbers(child)


def _version() -> str:
    from . import __version__

    return f"wavepaths {__version__}"


def _extra_commands() -> list[tuple[str, Callable]]:
    """Subcommands that live in their own modules (coverage, validate, bench): (name, the hook
    that adds its parser). Looked up per parser, so that ``main`` can run more than once in a
    process (it appended to a module-level list, and a second parser met the same subcommand twice)."""
    hooks = []
    for module, name in (("wavepaths.coverage.cli", "coverage"), ("wavepaths.validation.cli", "validate"),
                         ("wavepaths.bench.cli", "bench")):
        try:
            mod = __import__(module, fromlist=["add_parser"])
        except ImportError:
            continue
        hooks.append((name, mod.add_parser))
    return hooks


def _prepare_out(args) -> str | None:
    """Create the output folder of the commands that take one (``--out DIR``: coverage, validate,
    bench) before any work, so that a path that cannot be a folder (an existing file, a path
    under one) is a clear error up front, not a traceback after a long computation. Return the
    folder when this call created it (:func:`main` removes it again, empty, if the run fails)."""
    out = getattr(args, "out", None)
    if out is None:
        return None
    created = not os.path.exists(out)
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as exc:
        raise WavepathsError(f"--out {out!r} cannot be used as an output folder ({exc.strerror or exc})") from None
    return out if created else None


# the API's names of settings whose flag is not the name with dashes
_FLAG_OF = {"frequency_hz": "--frequency", "cell_size": "--cell", "tx_antenna": "--tx-antenna",
            "rx_antenna": "--rx-antenna", "replacements": "--replace-material"}


def _in_flags(message: str, parser: argparse.ArgumentParser, command: str) -> str:
    """An API error message in the command line's words: each backticked setting that is a
    flag of ``command`` (```launch_fan``` -> ``--launch-fan``, ```cell_size``` -> ``--cell``)
    is named by its flag (a review found `cell_size` where the user had typed --cell)."""
    flags: set[str] = set()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction) and command in action.choices:
            flags = {o for a in action.choices[command]._actions for o in a.option_strings}

    def flag(match: re.Match) -> str:
        name = match.group(1)
        candidate = _FLAG_OF.get(name, "--" + name.replace("_", "-"))
        return candidate if candidate in flags else match.group(0)

    return re.sub(r"`([a-z][a-z0-9_]*)`", flag, message)


def _remove_if_empty(folder: str | None) -> None:
    """Remove a folder this run created and left empty (a run that failed before writing)."""
    if folder is not None:
        try:
            os.rmdir(folder)  # only an empty folder goes
        except OSError:
            pass


def _first_run_notice(args) -> None:
    """Say so on stderr when the compiled kernels have never been cached: the first search
    then compiles them (about a minute here), which looks like a hang otherwise."""
    if args.command not in ("paths", "coverage", "validate", "bench"):
        return
    import importlib.util

    if importlib.util.find_spec("numba") is None:  # no numba: the numpy references, nothing to compile
        return
    # numba caches beside the sources, or under NUMBA_CACHE_DIR when set (its own tree)
    custom = os.environ.get("NUMBA_CACHE_DIR")
    cache = os.path.join(os.path.dirname(os.path.abspath(__file__)), "search", "__pycache__")
    if custom:
        import glob

        warm = bool(glob.glob(os.path.join(custom, "**", "*_numba*.nbi"), recursive=True))
    else:
        warm = os.path.isdir(cache) and any(f.endswith(".nbi") for f in os.listdir(cache))
    if not warm:
        print("wavepaths: compiling the numba kernels on first use (about a minute, once; cached for later runs)",
              file=sys.stderr)


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning on the command line: one plain line on standard error, without the Python
    file and source line it was raised from (restored when :func:`main` returns)."""
    name = getattr(category, "__name__", "Warning")
    kind = "warning" if name in ("WavepathsWarning", "UserWarning") else name
    print(f"wavepaths: {kind}: {message}", file=sys.stderr if file is None else file)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    created, status = None, 1
    try:
        created = _prepare_out(args)
        _first_run_notice(args)
        with warnings.catch_warnings():
            warnings.simplefilter("default")
            warnings.showwarning = _show_warning
            status = int(args.func(args) or 0)
            return status
    except WavepathsError as exc:
        print(f"wavepaths {args.command}: error: {_in_flags(str(exc), parser, args.command)}", file=sys.stderr)
        status = 2
        return status
    except MemoryError as exc:
        print(f"wavepaths {args.command}: error: out of memory ({exc}); ask for less at once: fewer receivers "
              "or cells, fewer --launch-rays or a smaller --launch-fan, a lower order", file=sys.stderr)
        status = 2
        return status
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        status = 130
        return status
    except BrokenPipeError:  # the reader went away (`wavepaths info ... | head`): not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        status = 0
        return status
    finally:
        if status != 0:
            _remove_if_empty(created)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
