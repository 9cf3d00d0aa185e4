"""``clusterfilter simulate``: write a simulated MMAUD-like recording.

Frames are rendered and written one at a time, so any duration fits in memory.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "simulate",
        help="simulate an MMAUD-like recording (Mid360 + Avia, drone, distractors, GT)",
        description="Ray-cast a car-park scene with a flying drone, people, a car, birds "
        "and swaying trees into Livox Mid360 and Avia frames, with total-station ground "
        "truth of a prism on the drone, and write it as a challenge sequence folder "
        "(zero-padded to the real row counts) or a ROS 1/ROS 2 bag. Deterministic for a "
        "given scenario, seed, duration and drone. See docs/simulator.md.",
    )
    p.add_argument("output", metavar="OUT", nargs="?", help="folder (mmaud, rosbag2) or .bag")
    p.add_argument("--scenario", default="default", help="scenario name (see --list)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default %(default)s)")
    p.add_argument("--duration", type=float, help="seconds (default: the scenario's length)")
    p.add_argument("--drone", help="drone model: mavic2, mavic3, phantom4, avata, m300")
    p.add_argument(
        "--format",
        choices=("mmaud", "rosbag2", "rosbag1"),
        default="mmaud",
        help="output format (default %(default)s)",
    )
    p.add_argument(
        "--prism-offset",
        type=float,
        default=0.25,
        help="height of the ground-truth prism above the drone's body centre, m (%(default)s)",
    )
    p.add_argument("--preview", metavar="PNG", help="also draw top/side views to this PNG")
    p.add_argument(
        "--truth",
        metavar="NPZ",
        help="also save the dense drone truth and per-frame drone point counts (.npz)",
    )
    p.add_argument("--list", action="store_true", help="list the scenarios and drones, then exit")
    p.add_argument("--overwrite", action="store_true", help="replace an existing OUT")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _list() -> None:
    from clusterfilter_ros.sim.actors import DRONE_MODELS
    from clusterfilter_ros.sim.scenarios import SCENARIOS

    print("scenarios:")
    width = max(len(n) for n in SCENARIOS)
    for name, spec in SCENARIOS.items():
        drone = spec.drone or "-"
        print(f"  {name:<{width}}  {spec.duration:6.0f} s  {drone:<8}  {spec.description}")
    print("drones (length x width x height, m):")
    for name, m in DRONE_MODELS.items():
        print(f"  {name:<8}  {m.length:.3f} x {m.width:.3f} x {m.height:.3f}")


def run(args: argparse.Namespace) -> int:
    if args.list:
        _list()
        return 0
    import math

    from tqdm import tqdm

    from clusterfilter_ros.errors import InputError, ParameterError
    from clusterfilter_ros.io.atomic import atomic_output_path
    from clusterfilter_ros.io.dataset import write_output_frames
    from clusterfilter_ros.sim.preview import PreviewCollector, draw_preview
    from clusterfilter_ros.sim.scenarios import PAD_ROWS, Simulation

    if not args.output:
        raise InputError("give an output path OUT (or --list to see the scenarios)")
    if not math.isfinite(args.prism_offset):
        raise ParameterError(f"--prism-offset must be a finite number, got {args.prism_offset}")
    out_path = Path(args.output)
    if out_path.exists() and not args.overwrite:
        raise InputError(f"output {out_path} already exists (use --overwrite to replace it)")
    for extra, suffix in ((args.preview, ".png"), (args.truth, ".npz")):
        if extra and not Path(extra).suffix.lower() == suffix:
            raise InputError(f"{extra}: expected a {suffix} file name")
        if extra:
            # Checked before the main output is written, so that a bad extra path does
            # not stop the command half-way with the sequence already on disk.
            parent = Path(extra).resolve().parent
            try:
                parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise InputError(f"{extra}: cannot create its folder ({exc.strerror})") from None
            if Path(extra).is_dir():
                raise InputError(f"cannot write {extra}: it is a folder")
            if not os.access(parent, os.W_OK | os.X_OK):
                raise InputError(f"cannot write {extra}: {parent} is not writable")
    sim = Simulation(
        args.scenario,
        seed=args.seed,
        duration=args.duration,
        drone=args.drone,
        prism_offset=(0.0, 0.0, args.prism_offset),
    )
    ground_truth = sim.ground_truth()
    total = sum(sim.frame_count(s) for s in sim.sensors)
    if total == 0:
        raise ParameterError(f"--duration {sim.duration:g} s is shorter than one 0.1 s lidar frame")
    collector = PreviewCollector(expected_frames=total, seed=args.seed) if args.preview else None
    counts: list[tuple[float, str, int, int]] = []

    def frames():
        for sf in sim.iter_frames():
            f = sf.frame
            counts.append((f.stamp, f.sensor, len(f), int(sf.drone_mask.sum())))
            if collector is not None:
                collector.add(f.xyz, sf.classes, f.sensor, f.stamp)
            yield f

    writer_kw: dict = {"pad_rows": PAD_ROWS} if args.format == "mmaud" else {}
    with tqdm(
        total=total,
        unit="frame",
        desc=f"simulate {args.scenario}",
        disable=args.quiet,
        file=sys.stderr,
    ) as bar:
        out = write_output_frames(
            frames(),
            out_path,
            fmt=args.format,
            ground_truth=ground_truth if len(ground_truth) else None,
            overwrite=args.overwrite,
            progress=bar.update,
            **writer_kw,
        )
    drone_truth = sim.drone_truth()
    if args.truth:
        with atomic_output_path(args.truth, suffix=".npz") as tmp_truth:
            _save_truth(tmp_truth, args, sim, drone_truth, counts)
    if collector is not None:
        model = sim.drone.model.name if sim.drone is not None else "no drone"
        with atomic_output_path(args.preview, suffix=".png") as tmp_preview:
            draw_preview(
                tmp_preview,
                collector,
                drone_truth,
                ground_truth,
                {s.sensor: s.origin for s in sim.sensors},
                f"{args.scenario} (seed {args.seed}, {sim.duration:g} s, {model})",
            )
    drone_pts = sum(c[3] for c in counts)
    print(
        f"simulate: wrote {len(counts)} frames ({drone_pts} drone points) and "
        f"{len(ground_truth)} ground-truth positions to {out}"
        + (f"; preview {args.preview}" if args.preview else "")
    )
    return 0


def _save_truth(path, args: argparse.Namespace, sim, drone_truth, counts) -> None:
    """The dense drone truth and per-frame drone point counts as one .npz file."""
    import numpy as np

    np.savez_compressed(
        path,
        stamps=drone_truth.stamps,
        xyz=drone_truth.xyz,
        frame_stamps=np.array([c[0] for c in counts]),
        frame_sensors=np.array([c[1] for c in counts]),
        frame_points=np.array([c[2] for c in counts]),
        frame_drone_points=np.array([c[3] for c in counts]),
        prism_offset=sim.prism_offset,
        scenario=args.scenario,
        seed=args.seed,
    )
