"""One definition of every tunable parameter: name, type, default, range, description.

The same :class:`ParamSpec` objects drive
- the ROS node (``declare_parameter`` with descriptors and ranges, run-time validation),
- ``config/detector.yaml`` (generated from them; a test keeps the file in sync),
- the CLI (``--param name=value`` and ``--params-file``),
- the README parameter table (``clusterfilter params --markdown``).

Detector (core) parameters are listed in :data:`DETECTOR_PARAMS`; node-only parameters
(topics, frames, extrinsics) live in ``clusterfilter_ros.ros.node_params`` using the same
class. This module is ROS-free.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from clusterfilter_ros.errors import ParameterError

ParamValue = bool | int | float | str | list[float] | list[str]


@dataclass(frozen=True)
class ParamSpec:
    """Definition of one parameter.

    ``kind`` is one of ``bool``, ``int``, ``float``, ``str``, ``float_list``, ``str_list``.
    ``minimum``/``maximum`` bound numbers (and every element of a float list);
    ``length`` fixes the length of a list; ``choices`` restricts strings (and every
    element of a string list).
    """

    name: str
    kind: str
    default: ParamValue
    description: str
    minimum: float | None = None
    maximum: float | None = None
    choices: tuple[str, ...] | None = None
    length: int | None = None
    group: str = "detector"
    read_only: bool = False

    def validate(self, value: Any) -> ParamValue:
        """Return ``value`` coerced to this parameter's type, or raise :class:`ParameterError`."""
        try:
            coerced = _coerce(self.kind, value)
        except (TypeError, ValueError) as exc:
            raise ParameterError(
                f"parameter '{self.name}' expects {self.kind}, got {value!r} ({exc})"
            ) from None
        items = coerced if isinstance(coerced, list) else [coerced]
        if self.length is not None and isinstance(coerced, list) and len(coerced) != self.length:
            raise ParameterError(
                f"parameter '{self.name}' needs {self.length} values, got {len(coerced)}"
            )
        for item in items:
            if isinstance(item, float) and not math.isfinite(item):
                raise ParameterError(f"parameter '{self.name}' must be finite, got {item!r}")
            if isinstance(item, (int, float)) and not isinstance(item, bool):
                if self.minimum is not None and item < self.minimum:
                    raise ParameterError(
                        f"parameter '{self.name}' = {item} is below its minimum {self.minimum}"
                    )
                if self.maximum is not None and item > self.maximum:
                    raise ParameterError(
                        f"parameter '{self.name}' = {item} is above its maximum {self.maximum}"
                    )
        if self.choices is not None:
            # A string must be one of the choices; a string list may only hold choices.
            bad = [v for v in items if v not in self.choices]
            if bad:
                raise ParameterError(
                    f"parameter '{self.name}' = {coerced!r}: {bad[0]!r} is not one of "
                    f"{list(self.choices)}"
                )
        return coerced

    def range_text(self) -> str:
        if self.choices:
            return " | ".join(self.choices)
        if self.minimum is None and self.maximum is None:
            return ""
        lo = "" if self.minimum is None else _fmt(self.minimum)
        hi = "" if self.maximum is None else _fmt(self.maximum)
        return f"[{lo}, {hi}]"


def _fmt(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else repr(float(x))


def _coerce(kind: str, value: Any) -> ParamValue:
    if kind == "bool":
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("true", "false", "1", "0"):
            return value.lower() in ("true", "1")
        if isinstance(value, int) and value in (0, 1):
            return bool(value)
        raise ValueError("not a boolean")
    if kind == "int":
        if isinstance(value, bool):
            raise ValueError("boolean given")
        if isinstance(value, float) and not value.is_integer():
            raise ValueError("not a whole number")
        return int(value)
    if kind == "float":
        if isinstance(value, bool):
            raise ValueError("boolean given")
        return float(value)
    if kind == "str":
        if not isinstance(value, str):
            raise ValueError("not a string")
        return value
    if kind == "float_list":
        if isinstance(value, str):
            value = [v for v in value.replace("[", "").replace("]", "").split(",") if v.strip()]
        return [float(_coerce("float", v)) for v in value]
    if kind == "str_list":
        if isinstance(value, str):
            value = [v.strip() for v in value.split(",") if v.strip()]
        return [str(v) for v in value]
    raise ValueError(f"unknown parameter kind {kind}")


class ParamSet:
    """Validated values for a list of :class:`ParamSpec`, accessible as attributes."""

    def __init__(self, specs: Iterable[ParamSpec], values: Mapping[str, Any] | None = None):
        object.__setattr__(self, "_specs", {s.name: s for s in specs})
        object.__setattr__(self, "_values", {n: s.default for n, s in self._specs.items()})
        if values:
            self.update(values)

    @property
    def specs(self) -> dict[str, ParamSpec]:
        return dict(self._specs)

    def update(self, values: Mapping[str, Any]) -> None:
        """Validate and set several values at once; nothing changes if any is invalid."""
        staged = dict(self._values)
        for name, value in values.items():
            if name not in self._specs:
                raise ParameterError(f"unknown parameter '{name}'")
            staged[name] = self._specs[name].validate(value)
        object.__setattr__(self, "_values", staged)

    def as_dict(self) -> dict[str, ParamValue]:
        return {k: (list(v) if isinstance(v, list) else v) for k, v in self._values.items()}

    def copy(self, **overrides: Any) -> ParamSet:
        new = type(self)(self._specs.values(), self._values)
        if overrides:
            new.update(overrides)
        return new

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            # Private and special names are never parameters; copy and pickle look for
            # them (e.g. __setstate__) on an instance whose _values is not set yet.
            raise AttributeError(name)
        try:
            return self._values[name]
        except KeyError:
            raise AttributeError(name) from None

    def __setattr__(self, name: str, value: Any) -> None:
        self.update({name: value})

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self._values})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, ParamSet) and self._values == other._values


def parse_assignments(items: Iterable[str]) -> dict[str, str]:
    """Parse CLI ``name=value`` strings (values are validated later by the ParamSpec)."""
    out: dict[str, str] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise ParameterError(f"expected name=value, got '{item}'")
        out[name.strip()] = value.strip()
    return out


def markdown_table(specs: Iterable[ParamSpec]) -> str:
    """A Markdown table of parameters for the README."""
    rows = ["| name | type | default | range | description |", "|---|---|---|---|---|"]
    for s in specs:
        cells = [f"`{s.name}`", s.kind, f"`{s.default}`", s.range_text(), s.description]
        if s.read_only:
            cells[-1] += " Read-only."
        rows.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(rows)


__all__ = [
    "ParamSpec",
    "ParamSet",
    "ParamValue",
    "parse_assignments",
    "markdown_table",
    "DETECTOR_PARAMS",
    "detector_params",
    "PAPER_PRESET",
    "detector_param_specs",
]


def detector_param_specs() -> list[ParamSpec]:
    """The detector (core algorithm) parameters; see :data:`DETECTOR_PARAMS`."""
    return list(DETECTOR_PARAMS)


#: Parameters of the detection algorithm (offline and streaming). The core owns this
#: list. Where the paper's published code has a value, it is noted in the description;
#: defaults are the values tuned on simulator seeds 0-2 (see docs/detector.md).
DETECTOR_PARAMS: tuple[ParamSpec, ...] = (
    # --- input filtering and denoise (paper 3.1) ---
    ParamSpec(
        "mid360_min_z",
        "float",
        0.0,
        "Mid360 points at or below this height (m, output frame) are dropped as ground "
        "clutter; 0 is the Mid360's own height when the frame's origin is the Mid360, as "
        "in MMAUD and the simulator (1.75 m above the ground there).",
        minimum=-50.0,
        maximum=100.0,
    ),
    ParamSpec(
        "max_range",
        "float",
        500.0,
        "Points farther than this from the sensor origin (m) are dropped.",
        minimum=1.0,
        maximum=2000.0,
    ),
    ParamSpec(
        "denoise_sensors",
        "str_list",
        ["avia"],
        "Sensors whose points pass the density denoise (paper 3.1: the Avia); empty list = none.",
        choices=("avia", "mid360"),
    ),
    ParamSpec(
        "denoise_voxel",
        "float",
        2.0,
        "Voxel edge (m) of the denoise density count (3x3x3 voxel neighbourhood).",
        minimum=0.05,
        maximum=50.0,
    ),
    ParamSpec(
        "denoise_min_points",
        "int",
        3,
        "A point survives the denoise if its neighbourhood holds at least this many points "
        "(itself included) over the superimposed frames.",
        minimum=1,
        maximum=10000,
    ),
    ParamSpec(
        "denoise_window",
        "float",
        2.0,
        "Streaming: seconds of past frames superimposed for the denoise (offline uses all).",
        minimum=0.1,
        maximum=60.0,
    ),
    ParamSpec(
        "track_denoised",
        "bool",
        True,
        "Streaming: the live track also takes the returns the denoise dropped, at least "
        "denoised_min_range out, within track_gate of where it is heading, as it takes "
        "each frame's denoised returns: a far, fast drone's isolated Avia returns; the "
        "clustering never reads them; false = only the denoised points.",
    ),
    ParamSpec(
        "denoised_min_range",
        "float",
        40.0,
        "Streaming: the returns the denoise dropped that the live track (track_denoised) "
        "and the late output's growth (report_denoised) may take lie at least this far (m) "
        "from the output frame's origin: nearer, a drone gives several returns a frame and "
        "passes the denoise, and the sensor's spurious returns crowd there.",
        minimum=0.0,
        maximum=1000.0,
    ),
    # --- static-structure suppression (persistence form of the relative density) ---
    ParamSpec(
        "static_suppression",
        "bool",
        True,
        "Remove points in voxels occupied during >= static_min_bins time bins before "
        "clustering (walls, roofs, trees); false = the paper's pipeline.",
    ),
    ParamSpec(
        "static_voxel",
        "float",
        1.5,
        "Voxel edge (m) of the static-structure persistence map.",
        minimum=0.05,
        maximum=10.0,
    ),
    ParamSpec(
        "static_bin",
        "float",
        1.0,
        "Seconds per time bin of the persistence map.",
        minimum=0.05,
        maximum=60.0,
    ),
    ParamSpec(
        "static_min_bins",
        "int",
        3,
        "A voxel hit in at least this many distinct time bins is static.",
        minimum=1,
        maximum=64,
    ),
    ParamSpec(
        "static_dilation",
        "int",
        0,
        "Also drop points in voxels this many voxels away from a static one (0 or 1).",
        minimum=0,
        maximum=1,
    ),
    ParamSpec(
        "static_drift_span",
        "float",
        8.0,
        "Offline (streaming: stream_static_drift): a group of >= 3 touching static voxels "
        "whose median voxel was hit over at most this many seconds is kept, and so are >= 3 "
        "touching voxels each hit over at most this long that touch longer-hit structure: "
        "a drone drifting slowly, slowing into a hover or hovering beside a tree, not "
        "structure (0 = off).",
        minimum=0.0,
        maximum=600.0,
    ),
    ParamSpec(
        "stream_static_drift",
        "bool",
        True,
        "Streaming: static_drift_span applies to the persistence map too, each voxel's "
        "span read from its oldest and newest hit within global_window, and known only if "
        "the map watched the voxel unhit for static_drift_span seconds before (else long: "
        "structure at start-up, or seen again by a lidar after a pause of more than "
        "static_bin): a drone slowing into a hover over 3-4 voxels left the history, and "
        "the late output lost it; false = off.",
    ),
    ParamSpec(
        "hover_detection",
        "bool",
        True,
        "Keep small isolated groups of static voxels (at most hover_max_extent) and accept "
        "compact clusters seen in >= hover_min_frames frames without motion: hovering drones.",
    ),
    ParamSpec(
        "split_still",
        "bool",
        True,
        "Offline: cut a flying cluster below min_confidence that stayed in place for "
        "hover_min_seconds (within hover_max_extent) and flew too into before / stay / "
        "after, each scored alone (a drone that hovers, then flies off).",
    ),
    ParamSpec(
        "split_long",
        "float",
        4.0,
        "Offline: a flying candidate below min_confidence that lasted at least twice this "
        "many seconds is cut in time into pieces of about this length, each scored alone "
        "(a 12 s pass at 10 m/s whose turns raised its median fitted acceleration to 5.8 "
        "m/s^2); the default is min_track_seconds, so a piece is not scaled down for its "
        "duration; 0 = off.",
        minimum=0.0,
        maximum=600.0,
    ),
    ParamSpec(
        "split_cut_pieces",
        "bool",
        True,
        "Offline (needs split_merged): a piece that split_still cut off (before, stay, "
        "after) is split into kinematic tracks as a merged cluster is (split_min_extent, "
        "split_excess_residual): a bird that joined the drone's track for a second left "
        "the whole smooth enough not to be split, but the piece it falls in is rough, "
        "and scored zero. Not split_long's pieces (a long bird cluster's pieces split "
        "gave a bird's smooth leg); false = the pieces are left whole.",
    ),
    ParamSpec(
        "lead_in_gap",
        "float",
        10.0,
        "Offline: the drone's arrival, seen too briefly or sparsely to be selected alone "
        "(at least keep_confidence), is reported with the track it leads into if it "
        "ended at most this many seconds before the track's first selected piece began, "
        "its last returns within lead_in_reach of the piece's first ones, heading "
        "towards them, and able to stop there (link_max_accel): the drone stopped out "
        "of view, then went on from there; 0 = off.",
        minimum=0.0,
        maximum=600.0,
    ),
    ParamSpec(
        "stop_bridge_gap",
        "float",
        20.0,
        "Offline: between two selected pieces of a track more than extend_max_gap and at "
        "most this many seconds apart, a stay of returns too few to be scored (at least "
        "three frames within stream_hover_max_extent, scattering at most "
        "hover_max_scatter, above min_centroid_z) where the earlier piece was heading and "
        "the later one came from (within 60 degrees, and no farther than their speeds "
        "carry them by then) joins the earlier piece: a drone that flew on unseen, "
        "stopped 32 m out for 2 s, then flew on (deviation 132); 0 = off.",
        minimum=0.0,
        maximum=600.0,
    ),
    ParamSpec(
        "report_below_floor",
        "bool",
        True,
        "report_lag: the late output's growth at a track's ends (report_extend_head, "
        "report_extend_tail) also takes the Mid360's returns at or below mid360_min_z "
        "within one growth step of the track's first or newest sample, in voxels hit in "
        "fewer than static_min_bins time bins of the local history, across gaps of at "
        "most max_extrapolation, as offline's extend_below_floor does: a drone lifting "
        "off or touching down on the ground (deviation 135); false = the streaming "
        "detector drops those returns as frames arrive.",
    ),
    ParamSpec(
        "bridge_split_pieces",
        "bool",
        True,
        "Offline: where the kinematic split (split_merged) cut a cluster into pieces, "
        "the pieces too small or too unconfident to be selected that together carry one "
        "flight from a selected piece's end to the next selected piece's start are "
        "reported with them. Each piece must have a velocity at both ends, and each step "
        "must be at most link_max_gap long and lie where both ends were heading "
        "(link_gate + link_max_accel x gap^2 / 2 from where each end's velocity carries "
        "it): a drone's 17 and 9 returns between two pieces of its track, cut off by a "
        "bird's returns (deviation 134); false = not bridged.",
    ),
    ParamSpec(
        "bridge_end_gap",
        "float",
        1.3,
        "Offline: as bridge_split_pieces, beyond the track's ends: the pieces of split "
        "clusters that chain on from the last selected piece's end (or into the first "
        "one's start), each step at most this many seconds long and where both ends were "
        "heading, are reported with the track. A drone's returns after a half-second gap "
        "were in another cluster when the linker ran, and the split freed them too late "
        "to be linked; steps as long as link_max_gap took birds' legs 1.3-1.9 s from a "
        "track's end (deviation 147; 1.0 s until deviation 151); 0 = off.",
        minimum=0.0,
        maximum=10.0,
    ),
    ParamSpec(
        "stray_chord",
        "bool",
        True,
        "Offline trajectory: after the stray_distance refits, a lone track sample (two "
        "frame periods or more from both neighbours) farther than stray_distance plus "
        "link_max_accel x dt1 x dt2 / 2 from the chord between its neighbours (at most "
        "link_max_gap apart) is left out of a last fit, as the delayed output leaves it "
        "out: a noise return the clustering joined to a drone's track 0.6 s after one of "
        "its returns and 1.0 s before the next, 5.6 m off its path, which the smoothing "
        "spline passed through (deviation 136); false = only returns far from the "
        "fitted track are left out.",
    ),
    ParamSpec(
        "grow_from_fit",
        "bool",
        True,
        "Offline growth: a selected track's ends are judged (where it was heading, and "
        "from when) by its returns within stray_distance of its fitted trajectory only "
        "(the first and last 4 s of the track, each fitted on its own): "
        "a bird's seven returns crossing a fast pass's line began the pass's cluster, "
        "and growth back in time from the bird's end state left the drone's first "
        "returns as noise (deviation 137); false = by all of its returns but a lone "
        "stray end.",
    ),
    ParamSpec(
        "lead_in_reach",
        "float",
        10.0,
        "Offline: how far (m) the arrival's last returns may lie from the track's first "
        "ones for lead_in_gap.",
        minimum=0.0,
        maximum=1000.0,
    ),
    ParamSpec(
        "hover_max_extent",
        "float",
        3.0,
        "Largest bounding-box side (m) of a hovering-drone candidate.",
        minimum=0.1,
        maximum=50.0,
    ),
    ParamSpec(
        "hover_max_scatter",
        "float",
        0.35,
        "Largest scatter (m) of a hovering candidate: the median distance of its returns "
        "from the median position of the 7 returns nearest each in time. A drone's "
        "returns lie on its body also while it drifts or brakes into a hover (at most "
        "0.2 m in the simulator); a far tree crown seen a return at a time scatters "
        "0.45-0.85 m and passed as a drone hovering (deviation 106); 0 = off.",
        minimum=0.0,
        maximum=50.0,
    ),
    ParamSpec(
        "hover_min_frames",
        "int",
        15,
        "Frames a compact motionless cluster needs to count as a hovering drone, each with "
        "its returns' mean within hover_max_extent / 2 of the cluster's median position.",
        minimum=1,
        maximum=100000,
    ),
    ParamSpec(
        "hover_min_seconds",
        "float",
        2.0,
        "Time span (s) a compact cluster needs to count as a hovering drone (between the "
        "first and last of the frames hover_min_frames counts): a dense object close to the "
        "rig fills hover_min_frames (0.1 s bins) in 1.5 s while passing.",
        minimum=0.0,
        maximum=60.0,
    ),
    ParamSpec(
        "hover_keep_frames",
        "int",
        11,
        "Streaming: a hovering track being reported stays reported while its cluster has "
        "this many frames in place, counted as for hover_min_frames (hysteresis with "
        "keep_confidence; a new one needs hover_min_frames); values >= hover_min_frames "
        "switch this off.",
        minimum=1,
        maximum=100000,
    ),
    ParamSpec(
        "stream_hover_min_frames",
        "int",
        10,
        "Streaming: frames (and returns) a new hovering candidate needs instead of "
        "hover_min_frames (and stream_min_cluster_points) when its returns stay within "
        "stream_hover_max_extent: a small drone hovering 25-30 m away gives a return or "
        "two a second; values >= hover_min_frames switch this off.",
        minimum=1,
        maximum=100000,
    ),
    ParamSpec(
        "stream_hover_max_extent",
        "float",
        0.6,
        "Streaming: largest extent (m, 10th to 90th percentile on each axis) of a hovering "
        "candidate confirmed with stream_hover_min_frames: a small drone's body and its "
        "wind drift (0.1-0.4 m in the simulator), not the thin poles, far tree tops and "
        "roof edges the persistence map has not learnt yet (0.8-2.3 m along them). "
        "While stream_hover_min_frames is on, a return the clustering left as noise "
        "within half of this of a cluster no wider than this joins it (a drone hovering "
        "far away is seen in lone returns).",
        minimum=0.0,
        maximum=50.0,
    ),
    ParamSpec(
        "offline_tight_hover",
        "bool",
        True,
        "Offline: a tight, sparse hover is confirmed as streaming confirms it "
        "(stream_hover_min_frames frames within stream_hover_max_extent, and the lone "
        "returns at its spot within link_max_gap of its time span joined to its "
        "cluster): a drone stopping 30 m from the rig between two legs of its flight "
        "gives a return every half second, and its stay was left out (deviation 130); "
        "false = hover_min_frames only.",
    ),
    ParamSpec(
        "hover_max_contact",
        "float",
        0.5,
        "A cluster is taken for a hovering drone only if at most this share of its points "
        "lie in or next to (26 neighbours) a static_voxel of suppressed static structure: "
        "the swaying edge of a tree crown is compact and seen in many frames too. "
        "Streaming: nor does a fragment with a larger share continue a reported track "
        "across a gap (reacquire_join). 1 switches both off.",
        minimum=0.0,
        maximum=1.0,
    ),
    ParamSpec(
        "warmup",
        "float",
        3.0,
        "Streaming: no estimates during the first seconds of a stream, while the "
        "persistence map learns the scene (static_min_bins x static_bin seconds make a "
        "voxel static).",
        minimum=0.0,
        maximum=600.0,
    ),
    ParamSpec(
        "report_lag",
        "float",
        0.0,
        "Streaming: besides each frame's own estimate (from the data up to that frame), "
        "report every frame's position again this many seconds of stream time later, from "
        "the data up to then and the track's returns on both sides of the frame "
        "(fixed-lag smoothing): a drone is then reported from its first returns, not from "
        "the moment it is confirmed, and between returns the position is interpolated. "
        "Up to local_history (the track's returns reach no further back); 0 = off.",
        minimum=0.0,
        maximum=60.0,
    ),
    # --- global clustering (paper 3.2) ---
    ParamSpec(
        "clustering",
        "str",
        "voxel",
        "Global clusterer: 'voxel' (26-neighbour voxel connected components approximating "
        "DBSCAN) or 'dbscan' (scikit-learn DBSCAN on points, paper-faithful, slow; offline only).",
        choices=("voxel", "dbscan"),
    ),
    ParamSpec(
        "eps",
        "float",
        2.0,
        "DBSCAN neighbourhood radius (m) for clustering='dbscan' (paper code: 2.0).",
        minimum=0.05,
        maximum=20.0,
    ),
    ParamSpec(
        "min_samples",
        "int",
        3,
        "Points in the neighbourhood that make a point (dbscan) or voxel (voxel) a core "
        "(paper code: 10).",
        minimum=1,
        maximum=10000,
    ),
    ParamSpec(
        "cluster_voxel",
        "float",
        2.0,
        "Voxel edge (m) of the voxel clusterer; its 3x3x3 neighbourhood plays DBSCAN's eps "
        "ball (1.0 matches the paper's eps 2.0).",
        minimum=0.05,
        maximum=20.0,
    ),
    ParamSpec(
        "cluster_time",
        "float",
        0.5,
        "Voxel clusterer: seconds per time bin of space-time (x, y, z, t) voxels; points "
        "link only within +-1 bin. 0 = cluster space only (the paper's global cloud).",
        minimum=0.0,
        maximum=3600.0,
    ),
    ParamSpec(
        "link_max_gap",
        "float",
        2.0,
        "Track linking: longest time gap (s) across which a cluster can continue an "
        "earlier one (a sparse drone's fragments become one track); 0 = no linking.",
        minimum=0.0,
        maximum=60.0,
    ),
    ParamSpec(
        "link_gate",
        "float",
        1.5,
        "Track linking: distance (m) allowed between a fragment's start and the previous "
        "fragment's end carried forward by its velocity, before the time-gap allowances.",
        minimum=0.0,
        maximum=100.0,
    ),
    ParamSpec(
        "link_max_accel",
        "float",
        4.0,
        "Track linking: acceleration (m/s^2) a linked object may have had during the gap; "
        "the reach grows by link_max_accel * gap^2 / 2.",
        minimum=0.0,
        maximum=100.0,
    ),
    ParamSpec(
        "link_max_dv",
        "float",
        8.0,
        "Offline track linking: where both facing ends of two fragments have a velocity, "
        "the velocities may differ by at most this (m/s) plus link_max_accel * gap: a bird "
        "leg heading where a drone's track begins is not the drone (10 until deviation "
        "126: a bird at 14 m/s took over a 2.4 m/s drone's track 1 s after it hid); "
        "0 = off.",
        minimum=0.0,
        maximum=100.0,
    ),
    ParamSpec(
        "link_rest_speed",
        "float",
        2.0,
        "Track linking: where both facing ends have a velocity and one is at most this "
        "fast (m/s: at rest, a hover or a crown's scatter), the earlier end carried by the "
        "mean of the two velocities (starting or stopping at constant acceleration) must "
        "lie within the reach too: a bird leg whose start, carried back by its own "
        "velocity, reaches a crown's returns did not leave from them (deviation 128); "
        "0 = off.",
        minimum=0.0,
        maximum=100.0,
    ),
    ParamSpec(
        "link_max_speed",
        "float",
        15.0,
        "Track linking: fastest speed (m/s) of a linked object; the reach never exceeds "
        "link_gate + link_max_speed * gap.",
        minimum=0.0,
        maximum=200.0,
    ),
    ParamSpec(
        "link_fit_window",
        "float",
        1.0,
        "Track linking: seconds at each end of a fragment fitted by a straight line to "
        "give its start and end position and velocity.",
        minimum=0.05,
        maximum=60.0,
    ),
    ParamSpec(
        "link_passes",
        "int",
        4,
        "Offline track linking: rounds of linking, until nothing more links; in the "
        "second and later rounds whole chains link by their own end states (a "
        "single-frame fragment at a chain's end has no velocity, its chain has).",
        minimum=1,
        maximum=20,
    ),
    ParamSpec(
        "stream_link_max_dv",
        "float",
        0.0,
        "Streaming: link_max_dv for the local history's linking; 0 = off (measured at 10 "
        "and 8 on the spent seeds: small losses of detection, and a bird leg left alone "
        "was reported; docs/detector.md deviations 88 and 126).",
        minimum=0.0,
        maximum=100.0,
    ),
    ParamSpec(
        "stream_link_passes",
        "int",
        4,
        "Streaming: link_passes for the local history (each round joins chains whose end "
        "is a one-frame fragment; more rounds can also join short bird legs).",
        minimum=1,
        maximum=20,
    ),
    ParamSpec(
        "extend_max_gap",
        "float",
        1.5,
        "Offline: longest time gap (s) across which a selected track grows at its ends "
        "by returns lying where it was heading (at most link_max_gap); 0 = no growth.",
        minimum=0.0,
        maximum=60.0,
    ),
    ParamSpec(
        "extend_hover_gap",
        "float",
        3.0,
        "Offline: a selected track's end slower than min_speed (a hovering drone seen once "
        "every second or two) grows across gaps up to this (s) by returns within "
        "track_gate of where it was heading (as streaming re-acquires a slow track within "
        "reacquire_window); at or below extend_max_gap as any end, but past max_gap also "
        "only within track_gate.",
        minimum=0.0,
        maximum=60.0,
    ),
    ParamSpec(
        "extend_far_gap",
        "float",
        3.0,
        "Offline: a selected track's end moving away from viewpoint (forward in time; "
        "towards it, backward) at 3 m/s or more grows across gaps up to this (s) by a lone "
        "return at least 40 m out, farther than the end, near the line it was on, at a "
        "spot nothing else returned from a second before or after (a pass leaving the "
        "lidars' range, its last returns seconds apart); such a return's estimates take "
        "the track's velocity. At or below extend_max_gap, as any end.",
        minimum=0.0,
        maximum=60.0,
    ),
    ParamSpec(
        "extend_max_brake",
        "float",
        8.0,
        "Offline: hardest braking (m/s^2) along its velocity a selected track may have "
        "done when it grows at its ends (a drone stopping into a hover beyond the reach of "
        "link_max_accel): a return within link_gate of where the track would be, braked at "
        "link_max_accel to this (to a stop at most), joins it too; at or below "
        "link_max_accel nothing more than the linking reach.",
        minimum=0.0,
        maximum=100.0,
    ),
    ParamSpec(
        "extend_brake_hover",
        "bool",
        True,
        "Offline: a selected track's end still moving (at least min_speed) also grows "
        "across gaps up to extend_hover_gap by a return within link_gate of where it would "
        "have come to a stop braking between link_max_accel and extend_max_brake, when "
        "another return lies within link_gate of it in another frame at most max_gap "
        "away: a drone braking into a hover 30 m out, then seen there in lone returns "
        "(not a lone tree or noise return). The late output's growth uses it only with "
        "report_extend_brake; false = such ends grow across extend_max_gap only.",
    ),
    ParamSpec(
        "extend_stop_hover",
        "bool",
        True,
        "Offline: a return a braking end took across more than extend_max_gap "
        "(extend_brake_hover), where it would have stopped, is an end at rest: when it "
        "alone spans no velocity, growth goes on from it as from a hovering end "
        "(extend_hover_gap, track_gate), taking the hover's returns before a drone sped "
        "away from it (deviation 138); false = such a return's end grows no further than "
        "one frame.",
    ),
    ParamSpec(
        "extend_stay_scatter",
        "bool",
        True,
        "Growth at a track's ends (offline and the late output): the returns taken from "
        "the first step across more than extend_max_gap by a slow or braking end (a "
        "hover's pause) on, when at least three frames within hover_max_extent, must "
        "scatter no more than hover_max_scatter, as a hovering drone's do; otherwise "
        "they are given back: a tree crown's sparse returns beside the track's end "
        "(deviation 131); false = not checked.",
    ),
    ParamSpec(
        "extend_denoised",
        "bool",
        True,
        "Offline: a selected track's growth may also take the returns the denoise removed "
        "(outside static structure): a far drone's isolated Avia returns; false = only "
        "noise points and small clusters.",
    ),
    ParamSpec(
        "extend_below_floor",
        "bool",
        True,
        "Offline: a selected track's growth may also take Mid360 returns at or below "
        "mid360_min_z in voxels hit in fewer than static_min_bins time bins (a drone "
        "taking off or landing; ground, walls and parked things are persistent and stay "
        "out), across gaps of at most max_extrapolation (a person walking past after "
        "touchdown does not continue the track); false = the floor filter holds for "
        "growth too.",
    ),
    ParamSpec(
        "split_merged",
        "bool",
        True,
        "A flying cluster too wide to be one object (a drone and birds near it, joined "
        "by the clusterer: wider than max_local_extent, or than split_min_extent and "
        "below min_confidence) is split into kinematic tracks, each scored on its own; "
        "false = keep it whole.",
    ),
    ParamSpec(
        "split_min_extent",
        "float",
        0.5,
        "Splitting merged clusters, offline (streaming: stream_split_min_extent): a flying "
        "cluster wider than this (m, mean extent in its shortest local windows) and below "
        "min_confidence is split too; one wider than max_local_extent always is. A bird "
        "linked into a drone's track for a second or two widens it only 1.1-1.9 m, a few "
        "returns of a bird passing a hovering drone 0.6 m.",
        minimum=0.1,
        maximum=1000.0,
    ),
    ParamSpec(
        "split_excess_residual",
        "float",
        0.3,
        "Splitting merged clusters, offline only: a flying cluster below min_confidence "
        "whose excess residual (m, beyond the windows' expected scatter) is above this is "
        "split too, however narrow (a bird's returns joined to a drone's track make it "
        "irregular without widening it); 0 = off.",
        minimum=0.0,
        maximum=100.0,
    ),
    ParamSpec(
        "split_low_flying",
        "bool",
        True,
        "Splitting merged clusters: a cluster whose centroid is below min_centroid_z is "
        "split too when at least twice min_cluster_points of its returns are at least "
        "min_centroid_z high (a drone flying low over a person joined the person's "
        "cluster, whose low centroid then gated the whole out); false = the centroid "
        "alone decides.",
    ),
    ParamSpec(
        "split_apart",
        "float",
        3.0,
        "Splitting merged clusters: a confident flying cluster is split too when, in at "
        "least three frame samples, returns of two of its kinematic tracks of >= 8 returns "
        "each lie more than this many metres apart (a bird crossing the drone's path joined "
        "its cluster); 0 = off.",
        minimum=0.0,
        maximum=100.0,
    ),
    ParamSpec(
        "split_contact_apart",
        "bool",
        True,
        "Streaming: a wide flying cluster left whole for its contact with suppressed "
        "structure (more than 10% of its returns, motion coherence below 0.4) is split "
        "anyway when at least a tenth of its returns lie below min_centroid_z, its "
        "coherence is at least 0.2, and it is two objects as split_apart measures them "
        "(returns of two of its kinematic tracks more than split_apart apart in at least "
        "three frame samples): a drone passing low beside a walking person and a tree "
        "joined the person's cluster (deviation 148); false = contact alone decides.",
    ),
    ParamSpec(
        "split_contact_tracked",
        "bool",
        True,
        "Streaming (with split_contact_apart): once the reported track's samples span "
        "min_track_seconds, the cluster holding its recent returns near where it would be "
        "is tested the same way without the returns below min_centroid_z: a tracked drone "
        "that flew into birds beside their own static voxels stays whole otherwise "
        "(deviation 149).",
    ),
    ParamSpec(
        "stream_split_excess_residual",
        "float",
        1.0,
        "Streaming: split_excess_residual for the local history, for clusters of at least "
        "3 x stream_min_cluster_points points (a sparser cluster's excess residual is the "
        "scatter of a return or two per window); offline's 0.3 m let single birds of a "
        "split flock be reported live; 0 = off.",
        minimum=0.0,
        maximum=100.0,
    ),
    ParamSpec(
        "stream_split_min_extent",
        "float",
        2.5,
        "Streaming: split_min_extent for the local history (without the offline track "
        "confirmation, a flock split into single birds can be reported).",
        minimum=0.1,
        maximum=1000.0,
    ),
    ParamSpec(
        "stream_carry_gap",
        "float",
        1.5,
        "Streaming: when a re-clustering rebuilds the track from a cluster that ends more "
        "than max_extrapolation before the previous track's newer samples, those up to "
        "this many seconds after its end are carried over while each lies where the "
        "track's straight-line motion reaches (track_gate plus link_max_accel x dt^2 / 2); "
        "and a rebuilt sample within link_max_gap after the reported track's newest one "
        "that its motion does not reach is another object's. Otherwise the drone's newest "
        "samples were dropped and a bird's returns that later joined the cluster became "
        "the track (deviation 152). The drone's samples carried on the 2025 runs came "
        "0.5-1.3 s after the end, birds' 1.8-1.9 s; 0 = off.",
        minimum=0.0,
        maximum=10.0,
    ),
    ParamSpec(
        "stream_track_agree",
        "bool",
        True,
        "Streaming: when a re-clustering rebuilds the reported track from a cluster that "
        "still holds some of its samples, a new sample more than track_gate from where "
        "the reported track was at its time is another object's and is skipped: a bird "
        "that joined the drone's cluster as the drone left, in the seconds the track "
        "already covered; false = the rebuilt track is taken as it is.",
    ),
    ParamSpec(
        "stream_split_track",
        "bool",
        True,
        "Streaming (needs split_merged): when the cluster holding the reported track's "
        "recent returns fails keep_confidence, it is split into kinematic tracks; the one "
        "holding the recent returns near the track's predicted position continues the "
        "track if it also holds those near its newest sample, begins with the track "
        "(within track_window, or with at most a fifth of the track's samples before it: "
        "a bird's few returns began the drone's cluster) and alone passes keep_confidence: "
        "another object that "
        "joined the drone's cluster without making it wide or rough enough to be split "
        "as merged. false = the track is given up.",
    ),
    ParamSpec(
        "split_blob",
        "float",
        1.0,
        "Splitting merged clusters: edge (m) of the voxels whose connected components, "
        "within one frame sample, are one object's returns.",
        minimum=0.1,
        maximum=5.0,
    ),
    ParamSpec(
        "split_gate",
        "float",
        1.0,
        "Splitting merged clusters: distance (m) allowed between a return group and a "
        "track's predicted position, before the time-gap allowances of link_max_accel "
        "and link_max_speed.",
        minimum=0.1,
        maximum=20.0,
    ),
    ParamSpec(
        "voxel_size",
        "float",
        0.2,
        "Edge (m) of the voxels used for occupied volume, density and IoU (paper code: 0.2).",
        minimum=0.01,
        maximum=5.0,
    ),
    # --- candidate gates ---
    ParamSpec(
        "min_cluster_points",
        "int",
        20,
        "Offline: a global cluster with fewer points is not a candidate (paper code: 100; "
        "streaming has stream_min_cluster_points); smaller clusters can still join a "
        "selected track as it grows.",
        minimum=1,
        maximum=10000000,
    ),
    ParamSpec(
        "stream_min_cluster_points",
        "int",
        15,
        "Streaming: min_cluster_points for the re-clusterings (a new track has only its "
        "first seconds of returns).",
        minimum=1,
        maximum=10000000,
    ),
    ParamSpec(
        "max_cluster_points",
        "int",
        10000,
        "A global cluster with more points is not a candidate (paper code: 10000).",
        minimum=1,
        maximum=100000000,
    ),
    ParamSpec(
        "min_centroid_z",
        "float",
        1.5,
        "A global cluster whose centroid is lower (m) is not a candidate (paper code: 6.0).",
        minimum=-100.0,
        maximum=1000.0,
    ),
    ParamSpec(
        "min_volume",
        "float",
        0.0,
        "A global cluster occupying less volume (m^3 of voxel_size voxels) is not a "
        "candidate (paper code: 0.3).",
        minimum=0.0,
        maximum=100000.0,
    ),
    ParamSpec(
        "max_extent",
        "float",
        1000.0,
        "A global cluster whose bounding box is wider (m, largest side) than this over "
        "the window is not a candidate (1000 = off).",
        minimum=0.1,
        maximum=1000.0,
    ),
    ParamSpec(
        "max_local_extent",
        "float",
        4.0,
        "Normalized scoring only: a cluster whose points within one shortest local window "
        "span more than this (m, mean largest bounding-box side) is not a candidate "
        "(walls, trees, buildings).",
        minimum=0.1,
        maximum=1000.0,
    ),
    # --- local windows and scoring (paper 3.2-3.3) ---
    ParamSpec(
        "frames",
        "float_list",
        [2.0, 5.0, 10.0],
        "Local window lengths in frames (one frame = frame_period s); paper code: 2, 5, 10.",
        minimum=1.0,
        maximum=1000.0,
    ),
    ParamSpec(
        "frame_period",
        "float",
        0.1,
        "Seconds per lidar frame (10 Hz Livox); turns 'frames' into time windows.",
        minimum=0.001,
        maximum=10.0,
    ),
    ParamSpec(
        "scoring",
        "str",
        "normalized",
        "Cluster ranking: 'paper' (sum exp(R) + iou_weight * sum log(1/IoU)) or "
        "'normalized' (per-window means mapped to [0, 1], with temporal support).",
        choices=("paper", "normalized"),
    ),
    ParamSpec(
        "iou_weight",
        "float",
        1.0,
        "The paper's lambda: weight of the voxel IoU term against the density term.",
        minimum=0.0,
        maximum=100.0,
    ),
    ParamSpec(
        "iou_floor",
        "float",
        0.01,
        "IoU values are clamped to at least this before log(1/IoU) (log(1/0) is infinite); "
        "below 1, since the normalized score divides by log(1/iou_floor).",
        minimum=1e-6,
        maximum=0.99,
    ),
    ParamSpec(
        "coherence_window",
        "float",
        1.0,
        "Normalized scoring: seconds per window of the motion-coherence measure.",
        minimum=0.05,
        maximum=60.0,
    ),
    ParamSpec(
        "coherence_floor",
        "float",
        0.45,
        "Normalized scoring: clusters with motion coherence at or below this get zero "
        "confidence (static remnants and erratic birds measured 0.1-0.47 in simulation).",
        minimum=0.0,
        maximum=1.0,
    ),
    ParamSpec(
        "min_coherence",
        "float",
        0.7,
        "Normalized scoring: motion coherence (1 - window scatter / overall scatter) at "
        "which a cluster gets full confidence; less scales it down (static remnants ~0).",
        minimum=0.01,
        maximum=1.0,
    ),
    ParamSpec(
        "min_speed",
        "float",
        1.0,
        "Normalized scoring: apparent speed (m/s; cluster size over its time span) at "
        "which a cluster gets full confidence; slower scales it down (0: no scaling).",
        minimum=0.0,
        maximum=100.0,
    ),
    ParamSpec(
        "min_travel",
        "float",
        8.0,
        "Normalized scoring: a cluster this large (m, its bounding box's largest side) "
        "counts as moving however slowly it went (a drone drifting below min_speed; "
        "its coherence still has to show one object moving); 0 switches this off.",
        minimum=0.0,
        maximum=1000.0,
    ),
    ParamSpec(
        "residual_window",
        "float",
        2.0,
        "Normalized scoring: seconds per window of the smoothness measure (a quadratic fit "
        "of position against time per window; see smooth_residual).",
        minimum=0.2,
        maximum=60.0,
    ),
    ParamSpec(
        "smooth_residual",
        "float",
        0.35,
        "Normalized scoring: RMS 3D residual (m) of the per-window quadratic fit at or "
        "below which a cluster keeps full confidence. Drones fly smooth paths (simulated "
        "drone tracks 0.07-0.39 m, mostly body size and range noise); birds and swaying "
        "branches are erratic (0.3-2.5 m).",
        minimum=0.0,
        maximum=100.0,
    ),
    ParamSpec(
        "max_residual",
        "float",
        0.7,
        "Normalized scoring: quadratic-fit residual (m) at which the confidence reaches "
        "zero (linear ramp from smooth_residual); 100 switches the smoothness factor off.",
        minimum=0.0,
        maximum=100.0,
    ),
    ParamSpec(
        "smooth_excess",
        "float",
        0.25,
        "Normalized scoring: excess residual (m; sqrt(residual^2 - spread^2), spread the "
        "RMS scatter of a cluster's points within one frame) at or below which a cluster "
        "keeps full confidence. Simulated drones 0-0.28 m; sparse birds 0.27-0.41 m.",
        minimum=0.0,
        maximum=100.0,
    ),
    ParamSpec(
        "max_excess",
        "float",
        0.4,
        "Normalized scoring: excess residual (m) at which the confidence reaches zero "
        "(linear ramp from smooth_excess); 100 switches this factor off.",
        minimum=0.0,
        maximum=100.0,
    ),
    ParamSpec(
        "accel_window",
        "float",
        1.0,
        "Normalized scoring: seconds per window of the acceleration measure (a quadratic "
        "fit of position against time per window; see smooth_accel).",
        minimum=0.2,
        maximum=60.0,
    ),
    ParamSpec(
        "accel_phases",
        "int",
        8,
        "Normalized scoring: the acceleration windows are laid at this many offsets, "
        "accel_window / accel_phases apart, and the median is taken over all of them (a "
        "sliding window in effect: where a window edge falls does not decide); 1 = one grid.",
        minimum=1,
        maximum=16,
    ),
    ParamSpec(
        "smooth_accel",
        "float",
        3.0,
        "Normalized scoring, offline: mean fitted acceleration (m/s^2) at or below which a "
        "cluster keeps full confidence. Drones fly acceleration-limited paths (simulated: "
        "median 2.5, 90% below 5.2 over 1 s windows); birds weave (median 12). 4 until "
        "deviation 150: birds' straight legs at 4.1-5.5 were reported offline.",
        minimum=0.0,
        maximum=1000.0,
    ),
    ParamSpec(
        "stream_smooth_accel",
        "float",
        4.0,
        "Normalized scoring, streaming: smooth_accel for the re-clusterings (a track's "
        "first seconds fit a less certain acceleration).",
        minimum=0.0,
        maximum=1000.0,
    ),
    ParamSpec(
        "max_accel",
        "float",
        8.0,
        "Normalized scoring: mean fitted acceleration (m/s^2) at which the confidence "
        "reaches zero (linear ramp from smooth_accel); 1000 switches the factor off.",
        minimum=0.0,
        maximum=1000.0,
    ),
    ParamSpec(
        "min_support_frames",
        "int",
        15,
        "Normalized scoring: full confidence needs drone points in at least this many "
        "distinct frames; fewer scale the confidence down (a bird's leg seen in a "
        "handful of frames cannot reach min_confidence).",
        minimum=1,
        maximum=100000,
    ),
    ParamSpec(
        "min_track_seconds",
        "float",
        4.0,
        "Offline: a cluster seen for less than this many seconds (first to last point) has "
        "its confidence scaled by duration / min_track_seconds (track confirmation: a "
        "bird's straight leg lasts a few seconds, a flight longer); 0 = off.",
        minimum=0.0,
        maximum=600.0,
    ),
    ParamSpec(
        "split_rest_seconds",
        "float",
        2.0,
        "Offline: a qualifying piece of a split cluster that overlaps a selected track in "
        "time is kept for its returns outside the selected spans if those last at least "
        "this long (s; where a bird took the drone's track over, the drone's next piece "
        "starts while the old track still runs); any other such candidate needs "
        "min_track_seconds.",
        minimum=0.0,
        maximum=600.0,
    ),
    ParamSpec(
        "apart_segments",
        "bool",
        True,
        "Offline: a qualifying candidate that overlaps a selected track in time is judged "
        "another object flying elsewhere (never within 10 m of the track at the moments "
        "both are seen) segment by segment, its returns cut where they are more than "
        "max_gap apart: the segments elsewhere are left out, and so are the kinematic "
        "tracks of the rest too small to be a candidate (min_cluster_points); what "
        "remains is kept as any such candidate (a bird's returns 2 s before the drone's "
        "began the cluster of the drone's second half, and the whole cluster was dropped: "
        "deviation 141); false = the candidate is judged and dropped whole.",
    ),
    ParamSpec(
        "end_objects",
        "bool",
        True,
        "Offline: each track selected whole is split into kinematic tracks; one with "
        "fewer than min_cluster_points returns wholly after the largest one's last return "
        "(or before its first), beginning beyond the linking reach of where that end was "
        "heading, is another object the clusterer joined at the track's end and becomes "
        "noise, which growth takes back only where the track was heading (a bird flying "
        "past a leaving drone: the track turned and followed it for 0.8 s, deviation 142); "
        "false = the whole cluster is the track.",
    ),
    ParamSpec(
        "end_overlap_support",
        "bool",
        True,
        "Offline: a qualifying candidate that overlaps one end of a selected track in time "
        "(the track has no returns after the candidate's last, or none before its first), "
        "at least as confident and with at least three times the track's returns in its "
        "time span, takes that time: the track's returns there are trimmed (a bird that "
        "flew on beside the drone joined the drone's track while the drone's own returns "
        "formed the candidate, deviation 145); false = the candidate keeps only its time "
        "outside the track.",
    ),
    ParamSpec(
        "coherence_per_window",
        "bool",
        False,
        "Motion coherence weighs every coherence_window once (the cluster centroid is the "
        "mean of its window centroids, distances are averaged per window) instead of every "
        "return: a drone passing over the rig left most of its returns in its closest "
        "second and looked static (coherence 0.42, deviation 144); false = weighted by "
        "returns.",
    ),
    ParamSpec(
        "stream_min_track_seconds",
        "float",
        0.0,
        "Streaming: min_track_seconds for the clusters of the local history; every second "
        "of it delays the first report of a new drone; 0 = off.",
        minimum=0.0,
        maximum=600.0,
    ),
    ParamSpec(
        "min_confidence",
        "float",
        0.6,
        "Clusters and estimates below this confidence are not reported.",
        minimum=0.0,
        maximum=1.0,
    ),
    # --- trajectory and estimates (paper 3.4) ---
    ParamSpec(
        "max_gap",
        "float",
        1.0,
        "The trajectory is split where drone points are more than this many seconds apart; "
        "no estimate inside such gaps.",
        minimum=0.01,
        maximum=60.0,
    ),
    ParamSpec(
        "max_extrapolation",
        "float",
        0.5,
        "No estimate more than this many seconds beyond the first/last drone point.",
        minimum=0.0,
        maximum=10.0,
    ),
    ParamSpec(
        "stray_distance",
        "float",
        2.0,
        "Offline trajectory: returns of the selected clusters farther than this (m) from "
        "the fitted track are left out and the track fitted again (another object's "
        "returns joined to the drone's). Delayed output (report_lag): a track sample "
        "farther than this (plus link_max_accel x dt1 x dt2 / 2) from the chord between "
        "its neighbours is left out of the fit (offline too with stray_chord). 0 switches "
        "all of them off.",
        minimum=0.0,
        maximum=100.0,
    ),
    ParamSpec(
        "min_points",
        "int",
        1,
        "An estimate needs at least this many drone points within track_window seconds.",
        minimum=1,
        maximum=100000,
    ),
    ParamSpec(
        "track_window",
        "float",
        1.0,
        "Seconds of drone points the streaming position fit uses (and the support count).",
        minimum=0.05,
        maximum=30.0,
    ),
    ParamSpec(
        "track_recency",
        "float",
        0.5,
        "Streaming: in the fit of the position push() reports, each sample of the last "
        "track_window seconds weighs its point count times exp(-age / track_recency), "
        "age in seconds before the newest sample, so a start, stop or turn shows sooner; "
        "a moving track's quadratic then needs 4 samples over 0.4 s (else 6 over 0.6 s) "
        "and a curvature of at least two standard errors. Which returns join the track "
        "is decided on equal weights. 0 = equal weights.",
        minimum=0.0,
        maximum=30.0,
    ),
    ParamSpec(
        "track_gate",
        "float",
        2.0,
        "Streaming: new points within this distance (m) of the predicted position join the "
        "track between re-clusterings. Offline: inside a selected track's span, points of "
        "other clusters within it of the track's path join the track.",
        minimum=0.0,
        maximum=50.0,
    ),
    ParamSpec(
        "track_join_link",
        "float",
        1.0,
        "Streaming: a track sample is one object's returns, chained by steps of at most "
        "this (m): of a frame's points within track_gate of a moving live track's "
        "predicted position, those chained to the one nearest it join the track (a bird "
        "crossing 1-2 m from the drone is not averaged into its sample, nor drags the "
        "track after it); a rebuilt track's sample of half a frame holds its largest "
        "such group (a noise return 10 m off in the drone's cluster does not move the "
        "sample); 0 = every return within the gate, or in the half frame.",
        minimum=0.0,
        maximum=50.0,
    ),
    ParamSpec(
        "keep_confidence",
        "float",
        0.25,
        "Streaming: a track being reported stays reported after a re-clustering while the "
        "cluster continuing it (points within track_gate of its predicted position) has "
        "at least this confidence, though below min_confidence (hysteresis); values >= "
        "min_confidence switch this off. Offline: a piece of a split cluster with at least "
        "this confidence that continues a selected track (within extend_max_gap of its end "
        "or start, where one flight could go on) joins it.",
        minimum=0.0,
        maximum=1.0,
    ),
    ParamSpec(
        "hover_coast_seconds",
        "float",
        10.0,
        "Streaming: a reported track slower than min_speed (a hovering drone) that a "
        "re-clustering finds only as noise or as a cluster too small to be a candidate "
        "(nothing rejected for its shape or motion) stays reported at min_confidence, "
        "taking returns within track_gate, while its newest return is at most max_gap "
        "old, for up to this many seconds after a re-clustering last chose it; 0 "
        "switches this off.",
        minimum=0.0,
        maximum=600.0,
    ),
    ParamSpec(
        "reacquire_window",
        "float",
        3.0,
        "Streaming: how long after its newest return a reported track can still be picked "
        "up again: a track slower than min_speed takes a return within track_gate of its "
        "position, and at a re-clustering a cluster near where the track would be now (its "
        "last position moved on at its velocity, within track_gate + link_max_accel x "
        "dt^2 / 2) continues it with keep_confidence; 0 switches this off.",
        minimum=0.0,
        maximum=60.0,
    ),
    ParamSpec(
        "report_backfill",
        "float",
        7.0,
        "report_lag: a frame at which the live output has not reported anything yet waits "
        "up to this many seconds beyond report_lag for a track to be confirmed: a drone "
        "confirmed more than report_lag after its first returns is then reported late "
        "from those returns (once its live run has lasted report_backfill_min_run), all "
        "at once, in stamp order. The late output's delay is then up to report_lag + "
        "report_backfill; beyond local_history - report_lag nothing is gained; 0 = off.",
        minimum=0.0,
        maximum=60.0,
    ),
    ParamSpec(
        "report_backfill_min_run",
        "float",
        2.0,
        "report_backfill: the frames before a confirmation are reported late only once the "
        "live output's run of estimates (each within max_gap of the one before) that began "
        "with it has lasted this long (s): a bird leg reported live for a moment is not "
        "reported over its whole history. report_lag: a track a re-clustering rejects is "
        "still reported late, up to its newest live estimate, if the live output reported "
        "it over at least this long.",
        minimum=0.0,
        maximum=60.0,
    ),
    ParamSpec(
        "report_backfill_min_points",
        "int",
        100,
        "report_backfill: the frames before a confirmation are also reported late when the "
        "live run ended sooner than report_backfill_min_run, if the track they are "
        "estimated from holds at least this many returns: a drone confirmed in the last "
        "second of a close pass was seen in hundreds of returns, the short bird legs the "
        "live output reported for a moment in tens; 0 = off.",
        minimum=0,
        maximum=1_000_000,
    ),
    ParamSpec(
        "report_head_gap",
        "float",
        0.5,
        "report_lag: the late output leaves out a track's returns before a gap longer than "
        "this (s) where one object could not have gone on from them to the rest (the lines "
        "at the gap's two sides do not meet) and the live output never reported them: "
        "another object's returns the clustering joined to the drone's.",
        minimum=0.05,
        maximum=60.0,
    ),
    ParamSpec(
        "report_head_path",
        "bool",
        True,
        "report_lag: the late output leaves out a track's returns before its first live "
        "report that lie off the path its later returns trace back in time (farther than "
        "track_gate plus link_max_accel x dt^2 / 2 from the line through the next second "
        "of them; a return followed by a gap over max_gap is not judged): another "
        "object's returns that met the drone's path and began its cluster; false = keep "
        "them.",
    ),
    ParamSpec(
        "report_extend_head",
        "bool",
        True,
        "report_lag: the late output also reports the reported track's earlier returns that "
        "the clustering left as noise or in clusters too small to score, found by growing "
        "the track back in time as offline does (across gaps up to extend_max_gap, or "
        "extend_hover_gap for a hovering start; not extend_far_gap): a far approach gives "
        "a return or two a second. The live output does not use them; false = off.",
    ),
    ParamSpec(
        "report_grow_max_contact",
        "float",
        0.5,
        "report_lag: the late output's growth past the track's end (report_extend_tail) "
        "stops short of the first grown sample with more than this share of its returns "
        "in or next to (26 neighbours) a static_voxel voxel of static structure: the edge "
        "of a swaying crown the track went on into after the drone left. (Not before the "
        "track's start: far approaches pass that close to tree lines.) 1 = off.",
        minimum=0.0,
        maximum=1.0,
    ),
    ParamSpec(
        "report_extend_tail",
        "bool",
        True,
        "report_lag: the late output also reports the reported track's later returns that "
        "the clustering left as noise or in clusters too small to score, found by growing "
        "the track forward in time as offline does (across gaps up to extend_max_gap, or "
        "extend_hover_gap for a hovering end; extend_far_gap with report_extend_far), for "
        "the frames after the track's cluster ends, once the live output has reported "
        "the track up to within max_gap of that end and over at least "
        "report_lag_min_run: a pass leaving the lidars gives a return or two a second. "
        "The live output does not use them; false = off.",
    ),
    ParamSpec(
        "report_extend_far",
        "bool",
        True,
        "report_lag: the late output's growth past the track's end (report_extend_tail) "
        "also takes, as offline does, a lone return far out on the line of a pass leaving "
        "the lidars up to extend_far_gap after the track's last; and where a gap longer "
        "than max_gap, at most extend_far_gap (else link_max_gap), separates a track's "
        "first or last samples from the rest, those samples, if they span no velocity of "
        "their own, take the velocity of the chord across the gap (held still, an "
        "estimate beside such a return was 2-4 m off the pass); false = neither.",
    ),
    ParamSpec(
        "stream_keep_reported",
        "bool",
        True,
        "Streaming: a re-clustering whose first-ranked candidate is another object keeps "
        "the reported track when the track's own cluster is slower than min_speed (a "
        "hover's), has returns within max_gap of now and passes the hysteresis "
        "(keep_confidence), as it would with no other candidate: a drone leaving a hover "
        "scores low for a second, and a bird ranked above it took the live output over "
        "(deviation 139); false = the first-ranked candidate replaces it.",
    ),
    ParamSpec(
        "report_extend_brake",
        "bool",
        False,
        "report_lag: the late output's growth at the track's ends also takes, as offline "
        "does with extend_brake_hover, a return up to extend_hover_gap away where a "
        "moving end braking harder than link_max_accel would have stopped, confirmed by "
        "another return there (a drone braking into a hover 33 m out, seen next 1.5 s "
        "later); false = the late growth stays within extend_max_gap of a moving end. Off: "
        "on the spent seeds it gained three runs and lost three (a structure's returns "
        "taken at start-up, a bird's track carried on; docs/detector.md deviation 124).",
    ),
    ParamSpec(
        "report_fill",
        "bool",
        True,
        "report_lag: the late output also reads the returns inside a gap of the reported "
        "track longer than max_gap (where its samples support no estimate) that lie on "
        "its path, noise or in clusters too small to score (any cluster's with "
        "report_fill_clustered), found as offline fills a "
        "track (the linking reach over half the gap, at most track_gate from the chord): "
        "a far pass's single returns between the frames the clustering kept. The live "
        "output does not use them; false = off.",
    ),
    ParamSpec(
        "report_fill_clustered",
        "bool",
        True,
        "report_fill: the gaps are filled from the returns of other clusters too (within "
        "track_gate of the chord, as offline fills a track), not only from noise and "
        "clusters too small to score: a bird crossing a sparse hover joined the hover's "
        "returns of the next seconds into its cluster, and the late output lost them "
        "(deviation 129); false = noise and small clusters only.",
    ),
    ParamSpec(
        "report_denoised",
        "bool",
        True,
        "report_lag: the late output's growth and fill (report_extend_head, "
        "report_extend_tail, report_fill) may also take the returns the denoise dropped, "
        "outside static structure, as offline's growth does (extend_denoised): a far, fast "
        "drone's isolated Avia returns, at least denoised_min_range out. They are kept for "
        "local_history (at most max_local_points); the clustering never reads them; false "
        "= only noise and small clusters of the history.",
    ),
    ParamSpec(
        "report_keep_newer",
        "bool",
        True,
        "report_lag: when a re-clustering selects a track whose newest return is older "
        "than the reported track's (an earlier cluster, the recent one rejected), the "
        "reported track's newer returns are kept for the late output as a dropped track's "
        "are: if the live output reported them over at least report_backfill_min_run, or "
        "they were lost; false = they are forgotten.",
    ),
    ParamSpec(
        "report_hold_new_runs",
        "bool",
        True,
        "report_lag: a frame before the first estimate of a new live run (no live estimate "
        "within link_max_gap before the frame) that falls due before that run (pauses up "
        "to link_max_gap included) has lasted as long as the frame is before it, at most "
        "report_backfill_min_run, waits as a backfilled frame does: estimated once the run "
        "has lasted that long (or from a track of report_backfill_min_points returns if it "
        "ends sooner), dropped otherwise. A bird leg the live output took up for a moment "
        "is not reported over the seconds before it. Needs report_backfill; false = such "
        "a frame is estimated when due while the run is going.",
    ),
    ParamSpec(
        "report_next_run",
        "bool",
        True,
        "report_lag: a held frame (backfilled, or before a new live run) whose live run "
        "ended too soon, and was not kept by report_backfill_min_points, waits for the "
        "next live run instead of being dropped: estimated once that run has lasted "
        "report_backfill_min_run, within the same report_backfill wait, from a track the "
        "live output reported in that run or one such a track could continue: the short "
        "run's object counts as confirmed only if the next run could be the same object. "
        "A drone the live output held for a moment before a pause is no reason to give up "
        "the frames before it. So does a frame that, when due, only a replaced track's "
        "newer returns reached (held live too briefly for report_keep_newer): it waits "
        "for the live run after the one that reported them. false = dropped.",
    ),
    ParamSpec(
        "report_next_dropped",
        "bool",
        True,
        "report_lag, with report_next_run: a reported track that a re-clustering dropped "
        "(no confident track after it) and that the live output held too briefly to keep "
        "(report_backfill_min_run) is treated as a replaced track's newer returns are: a "
        "frame it reached that, when due, no kept track reaches waits for the live run "
        "after the one that reported it, and is estimated from a track of that run or one "
        "such a track could continue, only within track_gate of where the dropped track "
        "was. A drone whose confidence dipped for a moment is no reason to give up the "
        "frames its track held. false = dropped.",
    ),
    ParamSpec(
        "report_bridge",
        "bool",
        True,
        "report_lag: a frame between two live reports on the same track at most "
        "link_max_gap apart is reported late although the live run after it was shorter "
        "than report_lag_min_run, when the run before it was not (a pass the live "
        "output let go in its sparse returns and took up again for a moment); false = "
        "such a frame waits for the run after it as any other.",
    ),
    ParamSpec(
        "report_lag_min_run",
        "float",
        0.5,
        "report_lag: a frame is reported late only if the live output's run of estimates "
        "(each within max_gap of the one before) that follows it lasted at least this "
        "long (s), or is still going when the frame is due: an object the live output "
        "reported for a moment is not reported over its whole history; 0 = off.",
        minimum=0.0,
        maximum=60.0,
    ),
    ParamSpec(
        "reacquire_join",
        "bool",
        True,
        "Streaming: within reacquire_window of a reported track's newest return, a "
        "cluster near where the track would be now that began after the track's cluster "
        "ended (the returns after a pause longer than link_max_gap) is scored joined with "
        "that cluster, and continues the track if its first returns lie where the track "
        "was heading (track_gate + link_max_accel x gap^2 / 2) and the joined cluster "
        "passes keep_confidence; false = such a fragment must be confirmed as a new track.",
    ),
    ParamSpec(
        "reacquire_newest",
        "bool",
        False,
        "Streaming (needs reacquire_join): where no recent return lies near where the "
        "reported track would be now, the cluster holding its newest returns (within "
        "track_window before its newest sample, within track_gate of it) is the fragment "
        "tried for the join: a drone 95 m up seen in bursts 0.5-1 s apart, whose last "
        "returns lay 7 m behind its predicted position, was given up (deviation 140); "
        "false = only returns near the predicted position count. Off: on 1073 streaming "
        "runs it gained in ten (live up to +5.1 points) and lost late in four (flyover "
        "3103 96.9 -> 82.7%: the joined track's end, a lone burst, does not grow, and "
        "the frames it fills are released only after a live report).",
    ),
    ParamSpec(
        "stream_segment_own",
        "bool",
        True,
        "stream_segment_contact: a segment whose centre lies within hover_max_extent of a "
        "sample of the reported track is the track's own and kept, whatever it touches "
        "(a hovering drone's voxels turn static; deviation 146); false = contact alone. "
        "Acts only with stream_segment_contact, which is off.",
    ),
    ParamSpec(
        "stream_segment_contact",
        "bool",
        False,
        "Streaming: the chosen track's segments (its returns cut where more than max_gap "
        "apart) with more than hover_max_contact of their returns in or next to "
        "suppressed static structure are left out of it, unless all are: the swaying edge "
        "of a tree crown, which the clusterer linked to a drone's cluster 1.75 s after the "
        "drone's returns stopped, was reported for 2.3 s (deviation 143); false = the "
        "whole cluster is the track. Off: a hovering drone's own voxels turn static, and "
        "on the first 514 streaming runs it cut hovering segments (birds 5901 late 58.5 "
        "-> 31.8%; take-off 2500 live 65.9 -> 57.0%, its hover 7.6 m up); with "
        "stream_segment_own the hovers are kept, but near birds a few of the drone's own "
        "returns are still cut (birds 5002 live 32.3 -> 28.6%).",
    ),
    ParamSpec(
        "reacquire_compete",
        "bool",
        True,
        "Streaming: where another selected cluster ranks first while the reported track "
        "continues in a fragment after a gap (reacquire_join), the track's earlier "
        "cluster (holding its returns before the fragment) joined with the fragment "
        "competes: if that joined cluster passes min_confidence and ranks higher "
        "(confidence x log(1 + frames)), the track is kept (a bird seen in more frames "
        "while a drone 80 m up was hidden for 2 s took over a track whose returns went "
        "on); false = the other cluster wins.",
    ),
    # --- streaming accumulator ---
    ParamSpec(
        "global_window",
        "float",
        20.0,
        "Streaming: seconds the persistence map (static suppression) remembers; at most 64 "
        "static_bin bins are used.",
        minimum=0.5,
        maximum=600.0,
    ),
    ParamSpec(
        "recluster_period",
        "float",
        0.5,
        "Streaming: seconds between global re-clusterings.",
        minimum=0.0,
        maximum=60.0,
    ),
    ParamSpec(
        "local_history",
        "float",
        10.0,
        "Streaming: seconds of non-static points kept and re-clustered (the global cloud "
        "of the streaming detector).",
        minimum=0.2,
        maximum=60.0,
    ),
    ParamSpec(
        "max_accumulator_voxels",
        "int",
        400000,
        "Streaming: cap on voxels in the persistence map (least-hit dropped first).",
        minimum=1000,
        maximum=100000000,
    ),
    ParamSpec(
        "max_local_points",
        "int",
        300000,
        "Streaming: cap on points in the local history (oldest frames dropped first).",
        minimum=1000,
        maximum=100000000,
    ),
    ParamSpec(
        "surface_depth",
        "float",
        0.0,
        "Every estimate is moved this far (m) away from viewpoint along the line of sight "
        "before target_offset: lidar returns lie on the side of the drone facing the "
        "sensors, so their centroid is nearer than the drone's centre.",
        minimum=0.0,
        maximum=2.0,
    ),
    ParamSpec(
        "viewpoint",
        "float_list",
        [0.0, 0.0, 0.0],
        "Where the lidars are (x, y, z in m, output frame), for surface_depth: the rig "
        "origin in the challenge data; the lidars' extrinsic translation in a map frame.",
        minimum=-100000.0,
        maximum=100000.0,
        length=3,
    ),
    ParamSpec(
        "target_offset",
        "float_list",
        [0.0, 0.0, 0.0],
        "Offset (x, y, z in m) added to every estimate, e.g. to a prism mounted on the drone.",
        minimum=-10.0,
        maximum=10.0,
        length=3,
    ),
)


#: The paper's published settings (ablation baseline): space-only clustering of the
#: whole cloud with its gates and ranking, no persistence suppression, no rejection.
PAPER_PRESET: dict[str, Any] = {
    "scoring": "paper",
    "static_suppression": False,
    "cluster_time": 0.0,
    "link_max_gap": 0.0,
    "split_merged": False,
    "mid360_min_z": 3.5,
    "min_samples": 10,
    "cluster_voxel": 1.0,
    "min_cluster_points": 100,
    "stream_min_cluster_points": 100,
    "max_cluster_points": 10000,
    "min_centroid_z": 6.0,
    "min_volume": 0.3,
    "min_confidence": 0.0,
}


def detector_params(values: Mapping[str, Any] | None = None) -> ParamSet:
    """A validated :class:`ParamSet` of the detector parameters (defaults + ``values``)."""
    return ParamSet(DETECTOR_PARAMS, values)
