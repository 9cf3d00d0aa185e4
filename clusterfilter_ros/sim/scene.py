"""The static surroundings of the rig: an open-air car park between buildings.

World frame: origin at the Mid360, x east, y north, z up; the ground is a plane
``GROUND_Z`` below the sensor (the rig stands on a tripod). Everything solid is made of
yaw-rotated boxes, vertical cylinders and ellipsoids (see :mod:`.geometry`). The layout
is fixed so the scene extent matches the MMAUD recordings (x, y about -70..90 m,
z -2..40 m); the seed varies which parking bays are taken, tree sizes and sway.

Trees: a trunk plus two or three overlapping porous ellipsoids of foliage. A ray that
enters the foliage stops after an exponentially distributed depth (mean free path
~0.5-0.8 m) or passes through, so leaf returns differ every frame. The foliage sways
(sum of two sinusoids, a few decimetres, periods of 2-6 s); the swaying volume is
moved linearly within each frame like any moving primitive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from clusterfilter_ros.sim.raycast import (
    CLASS_VEGETATION,
    PrimitiveBuilder,
    PrimitiveTable,
    angular_bounds,
)

GROUND_Z = -1.75
GROUND_REFLECTIVITY = 0.15

#: Parking rows: (y of the bay centre line, x from, x to); bays are 2.6 m wide.
PARKING_ROWS = (
    (-13.0, -34.0, 34.0),
    (-23.0, -34.0, 34.0),
    (13.0, -34.0, 30.0),
    (23.0, -34.0, 30.0),
)
#: Drive lanes of the car park (the moving car and people use them).
LANE_Y = (-18.0, 18.0, -33.0)
LANE_X = (-42.0, 44.0)


@dataclass
class Scene:
    """Static primitives, swaying foliage and the sensor-independent layout data."""

    ground_z: float
    ground_reflectivity: float
    static: PrimitiveTable
    foliage: PrimitiveTable
    sway_amplitude: np.ndarray  # (F, 2, 2) per foliage part: two terms, (x, y) amplitude
    sway_omega: np.ndarray  # (F, 2) rad/s
    sway_phase: np.ndarray  # (F, 2)
    _bounds: dict[tuple[float, float, float], tuple] = field(default_factory=dict)

    def foliage_offset(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Sway displacement (F, 3) and velocity (F, 3) of every foliage part at time t."""
        arg = self.sway_omega * t + self.sway_phase  # (F, 2)
        disp = np.zeros((len(self.foliage), 3))
        vel = np.zeros((len(self.foliage), 3))
        disp[:, :2] = (self.sway_amplitude * np.sin(arg)[:, :, None]).sum(axis=1)
        vel[:, :2] = (self.sway_amplitude * (self.sway_omega * np.cos(arg))[:, :, None]).sum(axis=1)
        return disp, vel

    def table_at(self, t: float) -> PrimitiveTable:
        """Static primitives plus the foliage where it is at time ``t`` (moving with sway)."""
        disp, vel = self.foliage_offset(t)
        foliage = PrimitiveTable(
            **{k: getattr(self.foliage, k) for k in PrimitiveTable.__dataclass_fields__}
        )
        foliage.centre = self.foliage.centre + disp
        foliage.velocity = vel
        return PrimitiveTable.concat([self.static, foliage])

    def bounds_from(self, origin: np.ndarray) -> tuple[np.ndarray, ...]:
        """Angular bounds of :meth:`table_at`'s rows seen from ``origin`` (cached)."""
        key = tuple(float(v) for v in origin)
        if key not in self._bounds:
            lo_s, hi_s = self.static.bounding_boxes(0.0)
            lo_f, hi_f = self.foliage.bounding_boxes(0.0)
            margin = np.zeros((len(self.foliage), 3))
            margin[:, :2] = np.abs(self.sway_amplitude).sum(axis=1)
            lo = np.concatenate([lo_s, lo_f - margin])
            hi = np.concatenate([hi_s, hi_f + margin])
            self._bounds[key] = angular_bounds(np.asarray(key), lo, hi)
        return self._bounds[key]


def _add_tree(
    builder: PrimitiveBuilder,
    foliage: PrimitiveBuilder,
    rng: np.random.Generator,
    x: float,
    y: float,
    height: float,
    crown: float,
) -> None:
    trunk_top = GROUND_Z + height * rng.uniform(0.35, 0.5)
    builder.cylinder(
        x, y, GROUND_Z, trunk_top + 0.5, rng.uniform(0.12, 0.25), 0.3, CLASS_VEGETATION
    )
    crown_mid = (trunk_top + GROUND_Z + height) / 2
    crown_half_h = (GROUND_Z + height - trunk_top) / 2
    for _ in range(int(rng.integers(2, 4))):
        off = rng.normal(0.0, 0.25 * crown, size=2)
        semi = (
            crown * rng.uniform(0.7, 1.0),
            crown * rng.uniform(0.7, 1.0),
            crown_half_h * rng.uniform(0.75, 1.0),
        )
        foliage.ellipsoid(
            (x + off[0], y + off[1], crown_mid + rng.normal(0, 0.2)),
            semi,
            reflectivity=rng.uniform(0.25, 0.4),
            label=CLASS_VEGETATION,
            yaw=rng.uniform(0, math.pi),
            mean_free_path=rng.uniform(0.5, 0.8),
        )


#: The tree beside the rig: trunk position, and how far (m) its overhanging branch's
#: centre is from the Avia's vertical axis. The branch's edge grazes the Avia's cone, so
#: as it sways the Avia sees from none to ~150 leaf returns a frame, as in MMAUD.
RIG_TREE_XY = (6.5, 4.0)
RIG_BRANCH_DISTANCE = 6.25
_AVIA_XYZ = (0.05, 0.25, 0.12)


def _add_rig_tree(builder: PrimitiveBuilder, foliage: PrimitiveBuilder) -> None:
    g = GROUND_Z
    tx, ty = RIG_TREE_XY
    builder.cylinder(tx, ty, g, g + 5.0, 0.2, 0.3, CLASS_VEGETATION)
    foliage.ellipsoid((tx, ty, g + 7.0), (2.5, 2.5, 2.2), 0.3, CLASS_VEGETATION, 0.0, 0.6)
    ax, ay, az = _AVIA_XYZ
    bearing = math.atan2(ty - ay, tx - ax)
    bx = ax + RIG_BRANCH_DISTANCE * math.cos(bearing)
    by = ay + RIG_BRANCH_DISTANCE * math.sin(bearing)
    foliage.ellipsoid((bx, by, az + 6.5), (1.2, 1.2, 0.9), 0.3, CLASS_VEGETATION, bearing, 0.6)


def build_car_park(rng: np.random.Generator) -> Scene:
    """The MMAUD-like car park around the rig (layout fixed, details drawn from ``rng``)."""
    b = PrimitiveBuilder()
    foliage = PrimitiveBuilder()
    g = GROUND_Z
    # Buildings (light concrete and glass): office block east, tower west, low block
    # north, garage south, and a far white tower south-east that only shows at long range.
    b.box((62.0, -30.0, g), (90.0, 42.0, g + 26.0), 0.45)
    b.box((-68.0, -55.0, g), (-56.0, 12.0, g + 40.0), 0.6)
    b.box((-30.0, 58.0, g), (36.0, 76.0, g + 12.0), 0.35)
    b.box((12.0, -70.0, g), (50.0, -52.0, g + 9.0), 0.5)
    b.box((78.0, -62.0, g), (90.0, -48.0, g + 38.0), 0.9)
    # Garage openings: a darker recessed band (just a thin slab proud of the face).
    b.box((12.0, -52.3, g + 2.5), (50.0, -52.0, g + 3.1), 0.8)
    # Boundary walls and a kerb.
    b.box((-48.0, -45.2, g), (8.0, -44.8, g + 1.6), 0.3)
    b.box((52.0, -48.0, g), (52.4, -32.0, g + 2.2), 0.3)
    b.box((-48.0, 44.8, g), (-32.0, 45.2, g + 1.6), 0.3)
    b.box((-44.0, -40.0, g), (-43.7, 40.0, g + 0.15), 0.25)
    # Covered parking: a roof on pillars west of the rig.
    b.box((-40.0, 28.0, g + 2.9), (-16.0, 40.0, g + 3.2), 0.3)
    for px in (-39.5, -31.5, -23.5, -16.5):
        for py in (28.5, 39.5):
            b.cylinder(px, py, g, g + 2.9, 0.25, 0.35)
    # Parked cars: body plus cabin, random occupancy and colour.
    for row_y, x0, x1 in PARKING_ROWS:
        for x in np.arange(x0, x1, 2.6):
            if rng.random() > 0.7:
                continue
            jitter_x = rng.normal(0, 0.15)
            jitter_y = rng.normal(0, 0.2)
            refl = rng.choice([0.08, 0.25, 0.5, 0.8])
            length, width = rng.uniform(4.2, 4.9), rng.uniform(1.75, 1.9)
            cx, cy = x + jitter_x, row_y + jitter_y
            b.box(
                (cx - width / 2, cy - length / 2, g + 0.15),
                (cx + width / 2, cy + length / 2, g + 0.95),
                refl,
            )
            b.box(
                (cx - width / 2 + 0.1, cy - length / 4, g + 0.95),
                (cx + width / 2 - 0.1, cy + length / 5, g + rng.uniform(1.4, 1.6)),
                0.1,
            )
    # Lamp posts along the lanes.
    for lx in (-36.0, -18.0, 0.0, 18.0, 36.0):
        for ly in (-18.0, 18.0):
            x, y = lx + 1.5, ly + 0.8
            b.cylinder(x, y, g, g + 8.0, 0.08, 0.4)
            b.box((x - 0.35, y - 0.12, g + 7.85), (x + 0.35, y + 0.12, g + 8.05), 0.5)
    # Trees: a row along the south wall, a group west, a few north, one beside the rig.
    trees = [(x, -40.0 + rng.normal(0, 0.5)) for x in np.arange(-38.0, 6.0, 9.0)]
    trees += [(-49.0 + rng.normal(0, 1), y) for y in np.arange(-30.0, 32.0, 10.0)]
    trees += [(-10.0, 48.0), (2.0, 50.0), (16.0, 47.0), (48.0, 30.0), (47.0, -10.0)]
    for tx, ty in trees:
        _add_tree(b, foliage, rng, tx, ty, rng.uniform(7.0, 12.0), rng.uniform(2.0, 3.5))
    _add_rig_tree(b, foliage)
    foliage_table = foliage.build()
    n_fol = len(foliage_table)
    # Crowns higher up sway more; two sinusoids per part.
    height_gain = np.clip((foliage_table.centre[:, 2] - g) / 8.0, 0.3, 1.5)
    sway_amplitude = rng.uniform(0.05, 0.15, size=(n_fol, 2, 2)) * height_gain[:, None, None]
    # The rig tree's overhanging branch swings in and out of the Avia's cone.
    sway_amplitude[-1] = rng.uniform(0.08, 0.14, size=(2, 2))
    sway_omega = 2 * np.pi / rng.uniform(2.0, 6.0, size=(n_fol, 2))
    sway_phase = rng.uniform(0, 2 * np.pi, size=(n_fol, 2))
    return Scene(
        ground_z=GROUND_Z,
        ground_reflectivity=GROUND_REFLECTIVITY,
        static=b.build(),
        foliage=foliage_table,
        sway_amplitude=sway_amplitude,
        sway_omega=sway_omega,
        sway_phase=sway_phase,
    )
