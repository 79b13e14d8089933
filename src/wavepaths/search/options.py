"""What to trace: one frozen options object shared by the path and coverage solvers."""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from ..errors import WavepathsError


CULLING_TESTS: dict[str, str] = {
    "keller_cone": "per receiver chunk, (source, dihedron) pairs whose Keller cones miss the chunk's sphere",
    "mirror_reach": "(receiver image, dihedron) pairs whose dihedron's Keller cones, from every source, miss the "
                    "bounding sphere of the image's last mirror",
    "receiver_mirror_side": "(receiver image, dihedron) pairs whose edge lies behind the image's last mirror",
    "receiver_beam": "(receiver image, dihedron) pairs whose edge lies outside the image's beam",
    "receiver_aperture": "(receiver image, dihedron) pairs whose edge lies outside the beams through the image's "
                         "mirrors' rectangles (compiled kernels only)",
    "keller_window": "(receiver image, dihedron) pairs whose diffraction point falls off the edge for every source",
    "reflection_beam": "(receiver, image chain) pairs whose receiver no beam of the chain can reach",
    "source_beam": "(transmitter image, dihedron) pairs whose edge lies outside the image's beam",
    "source_visibility": "(transmitter, dihedron) pairs whose edge is proven hidden from the transmitter, "
                         "(transmitter image, dihedron) pairs whose edge is proven hidden beyond the image's last "
                         "mirror, and candidates whose diffraction point lies in a proven shadow",
    "aperture_window": "(transmitter image, dihedron) pairs whose edge has no point from which a leg to the image "
                       "crosses its last mirror, and candidates whose diffraction point lies outside that window",
    "mirror_visibility": "(source, mirror) pairs of the image trees, transmitter's and receivers', whose mirror is "
                         "proven hidden from the source behind one convex polygon (no chain starts there)",
}
"""The conservative culling tests that :attr:`TraceOptions.disable_culling` can switch off."""

CULLING_COUNTERS: dict[str, str] = {
    "keller_cone": r"diffraction_\dr_\dr_source_pairs_culled_keller_cone",
    "mirror_reach": r"diffraction_\dr_\dr_receiver_pairs_rejected_mirror_reach",
    "receiver_mirror_side": r"diffraction_\dr_\dr_receiver_pairs_rejected_mirror_side",
    "receiver_beam": r"diffraction_\dr_\dr_receiver_pairs_rejected_beam",
    "receiver_aperture": r"diffraction_\dr_\dr_receiver_pairs_rejected_aperture",
    "keller_window": r"diffraction_\dr_\dr_receiver_pairs_rejected_keller_window",
    "reflection_beam": r"reflection_order_\d_culled_beam",
    "source_beam": r"diffraction_sources_order_\d_culled_beam",
    "source_visibility": r"diffraction_sources_order_\d_culled_hidden|diffraction_\dr_\dr_rejected_hidden",
    "aperture_window": r"diffraction_sources_order_\d_culled_aperture|diffraction_\dr_\dr_rejected_aperture",
    "mirror_visibility": r"(rx_)?images_order_1_culled_hidden",
}
"""The ``Paths.stats`` keys (regular expressions) under which each culling test counts what it drops."""


BOOLEAN_FIELDS = ("los", "diffraction", "lit_region", "skip_absorbers", "compiled", "free_edges")
"""The :class:`TraceOptions` fields that take ``True`` or ``False`` (Python or numpy booleans)."""


# upper bounds of the launched searches' sampling (32x and 256x the defaults): beyond them the
# rays' arrays alone take tens of GB, and a typo should be an error, not a swap storm
MAX_LAUNCH_RAYS = 1 << 26
MAX_LAUNCH_FAN = 1 << 16


CandidateMode = Literal["exhaustive", "launched"]
"""How candidates are found: every one by the image method and the closed form, or from rays
launched from the transmitter and the edges (docs/search.md)."""


@dataclass(frozen=True)
class TraceOptions:
    """Which propagation mechanisms to search for, and up to which order.

    Attributes
    ----------
    los : bool
        Line of sight.
    max_reflections : int
        Highest order of purely specular paths (0 to 6; the image tree grows as
        polygons ** order, pruned by visibility half-spaces).
    diffraction : bool
        First-order edge diffraction (seed §2.3 closed-form point, §3.3 validity).
    diffraction_reflections : int
        How many specular reflections may accompany the one diffraction, before
        and after it together (0: D only; 1: R-D and D-R; 2: also R-R-D, R-D-R,
        D-R-R). Total interactions of a diffracted path are ``1 + this``.
    lit_region : bool
        Keep diffracted paths whose receiver is lit by the incident field (outside
        the incident shadow boundary, ``|phi - phi'| < pi``). UTD needs them for a
        continuous total field; ``False`` keeps only the shadow region.
    skip_absorbers : bool
        Never reflect off polygons whose material is an absorber or free space (permittivity 1,
        conductivity 0): their reflections have zero amplitude.
    rx_batch : int
        Receivers processed per vectorised tile (memory vs. overhead).
    prune_db : float or None
        Drop reflected paths whose amplitude cannot exceed the free-space amplitude at
        the receiver's direct distance minus ``prune_db`` dB. The bound: a passive
        reflection has ``|Gamma| <= 1`` and the unfolded length of a chain is at least
        the distance from the receiver to its last image, so a chain with
        ``|rx - I_k| > 10^(prune_db / 20) |rx - tx|`` carries at most ``-prune_db`` dB
        relative to free space (isotropic antennas; with directive antennas add their
        peak gains). The dropped paths are counted in ``stats``
        (``pruned_paths_upper_bound``); their total power is at most
        ``pruned * 10^(-prune_db / 10)`` times the free-space power at the receiver's direct
        distance, so the power-sum path gain changes by at most
        ``10 log10(1 + pruned * 10^(-prune_db / 10))`` dB where it is at least free space's;
        below free space (no line of sight) the bound is the linear one, and a receiver whose
        only paths are pruned goes to no path. ``None`` keeps every path.
        Diffracted paths are pruned too when ``prune_frequency_hz`` is given, by the
        bound of :func:`wavepaths.search.diffraction._diffraction_amplitude_bound` (UTD with passive faces,
        :func:`wavepaths.em.utd.utd_magnitude_bound`; it holds for the ``"utd"`` model,
        textbook or Sionna compat, not for ``"gtd"``), counted in the same
        ``pruned_paths_upper_bound``.
    prune_frequency_hz : float or None
        The lowest frequency [Hz] the fields of these paths will be computed at, for the
        diffraction bound of ``prune_db`` (lower frequencies diffract more; the bound holds
        at every frequency above). ``None`` (default): ``prune_db`` never prunes diffracted
        paths. It is not filled in for you: on a map, diffraction that a free-space bound puts
        20 dB down is often all that reaches a shadowed cell (use ``tolerance_db`` there);
        :func:`wavepaths.coverage.coverage` sets it to the map's frequency with
        ``tolerance_db``, whose bound needs it (a ``prune_db`` given with it then prunes
        diffracted paths too). A map warns when ``prune_frequency_hz`` is above its
        frequency or its model is ``"gtd"``, where the bound does not hold.
    tolerance_db : float or None
        Coverage maps only (:func:`wavepaths.coverage.coverage`; :func:`wavepaths.trace`
        refuses it, having no fields): per transmitter and cell, drop diffracted
        contributions, weakest first, while the sum of their power bounds stays at most
        ``10^(tolerance_db / 10) - 1`` times the power of the cell's line-of-sight and
        reflected paths. The bound is the UTD one of ``prune_db`` (at the map's frequency,
        which coverage sets as ``prune_frequency_hz``) times the antennas' peak pattern
        amplitudes. The cell's power-sum total then changes by at most ``tolerance_db``
        dB; a cell that no line-of-sight or reflected path reaches loses nothing. Dropped
        candidates are counted in ``stats["tolerance_dropped_candidates"]``.
    disable_culling : frozenset of str
        Conservative culling tests to switch off, for measuring what each one saves
        (``wavepaths bench``'s skip benchmark); every name in :data:`CULLING_TESTS`. They
        never change the paths found, only the time taken: the benchmark checks that.
    compiled : bool
        Run the densest culling loops as compiled kernels when numba is installed (the
        ``fast`` extra; :mod:`wavepaths.search.kernels`); ``False`` runs the numpy
        reference. Both find the same paths.
    diffraction_candidates : str
        Where the diffracted candidates come from. ``"exhaustive"`` (default): every
        (source image, edge, receiver image) triple no conservative test rules out; every
        path is found. ``"launched"``: the sequences that Keller fans from sampled edge
        points carry to each receiver (:mod:`wavepaths.search.launch`), solved by the same
        exact tests (:mod:`wavepaths.search.launched`); far fewer candidates in dense
        scenes, but a sequence the sampling misses is missed (one transmitter per context).
        First-order diffraction without reflections (E-D-R) is enumerated as in
        ``"exhaustive"`` in both modes: only the chains with a reflection are sampled.
    launch_fan : int
        With ``"launched"``: Keller-cone directions per turn (denser: thinner tubes, fewer
        candidates, more rays).
    reflection_candidates : str
        The same choice for the purely specular paths: ``"exhaustive"`` (default: every
        receiver against every image chain whose beam can reach it), or ``"launched"``:
        the chains that ``launch_rays`` transmitter rays, reflected, carry to each receiver
        (:func:`wavepaths.search.launch.reflection_candidates_launched`), back-traced and
        cast like the others; a mirror the rays miss is missed (one transmitter per context).
    launch_rays : int
        With ``reflection_candidates="launched"``: rays from the transmitter.
    free_edges : bool
        Diffract on free edges too: edges of one face (the border of a screen or of a
        finite ground plane: a half-plane, ``n = 2``). Default ``True``: a free edge
        diffracts. ``False`` leaves them out (a ground plane whose border is only where the
        model stops). Sionna RT without ``edge_diffraction`` leaves out more: it counts an
        edge as free when no other face *of the same object* meets it, while wavepaths
        joins the faces of every object along an edge into one dihedron (an awning's edge
        along a wall is a wedge here, a free edge there; docs/search.md).
    """

    los: bool = True
    max_reflections: int = 2
    diffraction: bool = True
    diffraction_reflections: int = 1
    lit_region: bool = True
    skip_absorbers: bool = True
    rx_batch: int = 256
    prune_db: float | None = None
    prune_frequency_hz: float | None = None
    tolerance_db: float | None = None
    disable_culling: frozenset[str] = frozenset()
    compiled: bool = True
    diffraction_candidates: CandidateMode = "exhaustive"
    launch_fan: int = 256
    reflection_candidates: CandidateMode = "exhaustive"
    launch_rays: int = 1 << 21
    free_edges: bool = True

    def __post_init__(self) -> None:
        import numbers

        for name in ("max_reflections", "diffraction_reflections", "launch_rays", "launch_fan", "rx_batch"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                raise WavepathsError(f"`{name}` must be an integer, got {value!r}")
        for name in BOOLEAN_FIELDS:
            value = getattr(self, name)
            if not isinstance(value, (bool, np.bool_)):
                raise WavepathsError(f"`{name}` must be True or False, got {type(value).__name__} {value!r}")
        for name in ("prune_db", "prune_frequency_hz", "tolerance_db"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real)):
                raise WavepathsError(f"`{name}` must be a number or None, got {type(value).__name__} {value!r}")
        if isinstance(self.disable_culling, str):
            raise WavepathsError(f"`disable_culling` must be a set of culling test names, got the string "
                                 f"{self.disable_culling!r}; write {{{self.disable_culling!r}}}")
        object.__setattr__(self, "disable_culling", frozenset(self.disable_culling))
        unknown = self.disable_culling - set(CULLING_TESTS)
        if unknown:
            raise WavepathsError(f"unknown culling tests {sorted(unknown)}; known: {sorted(CULLING_TESTS)}")
        if self.prune_db is not None and not self.prune_db > 0:
            raise WavepathsError(f"`prune_db` must be positive or None, got {self.prune_db}")
        if self.tolerance_db is not None and not (np.isfinite(self.tolerance_db) and self.tolerance_db > 0):
            raise WavepathsError(f"`tolerance_db` must be positive or None, got {self.tolerance_db}")
        if self.prune_frequency_hz is not None and not (np.isfinite(self.prune_frequency_hz)
                                                        and self.prune_frequency_hz > 0):
            raise WavepathsError(f"`prune_frequency_hz` must be a positive frequency or None, got {self.prune_frequency_hz}")
        if not 0 <= self.max_reflections <= 6:
            raise WavepathsError(f"`max_reflections` must be in 0..6, got {self.max_reflections}")
        if not 0 <= self.diffraction_reflections <= 4:
            raise WavepathsError(f"`diffraction_reflections` must be in 0..4, got {self.diffraction_reflections}")
        if self.diffraction_candidates not in ("exhaustive", "launched"):
            raise WavepathsError(f"`diffraction_candidates` must be 'exhaustive' or 'launched', got "
                                 f"{self.diffraction_candidates!r}")
        if self.reflection_candidates not in ("exhaustive", "launched"):
            raise WavepathsError(f"`reflection_candidates` must be 'exhaustive' or 'launched', got "
                                 f"{self.reflection_candidates!r}")
        if not 16 <= self.launch_rays <= MAX_LAUNCH_RAYS:
            raise WavepathsError(f"`launch_rays` must be in 16..{MAX_LAUNCH_RAYS:,} (the default {1 << 21:,}; more "
                                 f"would take tens of GB), got {self.launch_rays:,}")
        if not 4 <= self.launch_fan <= MAX_LAUNCH_FAN:
            raise WavepathsError(f"`launch_fan` must be in 4..{MAX_LAUNCH_FAN:,} (the default 256; more would take "
                                 f"tens of GB), got {self.launch_fan:,}")
        if self.rx_batch < 1:
            raise WavepathsError(f"`rx_batch` must be positive, got {self.rx_batch}")

    def to_dict(self) -> dict:
        """JSON-ready fields (``disable_culling`` as a sorted list)."""
        d = {f: getattr(self, f) for f in self.__dataclass_fields__}
        d["disable_culling"] = sorted(self.disable_culling)
        return d

    def with_(self, **changes) -> "TraceOptions":
        """A copy with some fields changed."""
        return replace(self, **changes)

    @property
    def launched(self) -> bool:
        """Whether any candidates come from launched rays (``diffraction_candidates`` or
        ``reflection_candidates`` is ``"launched"``)."""
        return self.diffraction_candidates == "launched" or self.reflection_candidates == "launched"

    @property
    def max_depth(self) -> int:
        """The largest number of interactions any path may have."""
        d = self.max_reflections
        if self.diffraction:
            d = max(d, 1 + self.diffraction_reflections)
        return d


def check_trace_arguments(scene, options) -> TraceOptions:
    """The options of :func:`wavepaths.trace`, after checking the types of its arguments.

    A scene name or an options dict passed where objects are expected would otherwise fail
    deep inside the search, with an ``AttributeError``.

    Parameters
    ----------
    scene : Scene
        The scene argument; a name or a file is refused (load it with
        :func:`wavepaths.load_scene`).
    options : TraceOptions or None
        The options argument; None gives the default options.

    Returns
    -------
    TraceOptions
        ``options``, or ``TraceOptions()`` for None.

    Raises
    ------
    WavepathsError
        ``scene`` is not a :class:`~wavepaths.scene.model.Scene`, or ``options`` is neither a
        :class:`TraceOptions` nor None.
    """
    from ..scene.model import Scene

    if not isinstance(scene, Scene):
        hint = f"; load it first: wavepaths.load_scene({scene!r})" if isinstance(scene, (str, os.PathLike)) else ""
        raise WavepathsError(f"`scene` must be a Scene, got {type(scene).__name__}{hint}")
    if options is None:
        return TraceOptions()
    if not isinstance(options, TraceOptions):
        hint = "; write TraceOptions(**options)" if isinstance(options, dict) else ""
        raise WavepathsError(f"`options` must be a TraceOptions or None, got {type(options).__name__}{hint}")
    return options
