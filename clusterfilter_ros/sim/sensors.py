"""Scan patterns and return models of the two Livox lidars on the MMAUD rig.

Both sensors are fixed on a ground rig and report points in one shared world frame (the
frame the MMAUD points and ground truth share): origin at the Mid360, z up.

Mid360 (peripheral, 360 x -7..52 deg): every frame fires as many rays as the real file
has rows (19,968 / 20,064 alternately, ~200k pts/s at 10 Hz). The azimuth sweeps one
turn per frame with a start angle that advances by an irrational fraction of a turn
each frame; the elevation follows a Weyl (golden-ratio) sequence over the global ray
index. So no two frames fire the same directions (non-repetitive), and coverage of the
field of view fills in as frames accumulate, as on the real sensor.

Avia (conic, pointing up, 70.4 x 77.2 deg): 24,000 rays per frame (240k pts/s). Two
counter-rotating Risley prisms deflect the beam by equal angles, so the direction is the
sum of two opposite circular motions: a rosette whose petals pass through the centre;
with incommensurate prism rates it never repeats. Six lasers fire together with small
angular and phase offsets. The unit-disc rosette is scaled to the 70.4 x 77.2 deg field.

Return model (both): the detection range for a target of reflectivity rho follows the
data sheets' two points (R10 at 10 %, R80 at 80 %) as ``R10 * (rho/0.1)**k``. The
reflectivity is reduced by the cosine of the incidence angle (Lambertian) and, for
targets smaller than the beam footprint, by the fraction of the footprint they cover.
A logistic roll-off around that range gives the return probability. Ranges get Gaussian
noise and directions a small angular noise; points closer than the blind zone are
dropped. The Avia also reports sparse spurious returns in the open sky (the MMAUD Avia
noise reaching 300-400 m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clusterfilter_ros.core.frame import AVIA, MID360

GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0
SQRT2_FRAC = math.sqrt(2.0) - 1.0
#: Avia: rotation rates of the two Risley prisms (rev/s, opposite senses), incommensurate.
_PRISM_HZ = (61.803, -38.197)
_LASERS = 6
_ROSETTE_CACHE: dict = {}


@dataclass(frozen=True)
class LidarModel:
    """One Livox lidar: where it is, how it scans, how it returns points.

    Attributes:
        sensor: canonical name (``AVIA`` / ``MID360``).
        position: (x, y, z) of the optical centre in the world frame (m).
        rays_per_frame: ray counts per frame, cycled (the real file row counts).
        frame_period: seconds per frame (0.1 = 10 Hz).
        stamp_offset: delay of this sensor's frame stamps after the rig clock (s).
        stamp_jitter: standard deviation of the frame stamp jitter (s).
        range_at_10, range_at_80: data-sheet detection range (m) at 10 % / 80 % reflectivity.
        min_range: blind zone (m).
        range_sigma: range noise standard deviation (m).
        angle_sigma_deg: angular noise standard deviation (deg).
        beam_divergence_deg: (horizontal, vertical) full beam divergence (deg).
        max_return_probability: detection probability of a strong target well in range.
        fov_deg: field of view: Mid360 (azimuth span, el min, el max); Avia (h, v) full angles.
        sky_noise_per_frame: mean number of spurious sky returns per frame.
        sky_noise_range: (min, max) range of spurious returns (m).
    """

    sensor: str
    position: tuple[float, float, float]
    rays_per_frame: tuple[int, ...]
    frame_period: float
    stamp_offset: float
    stamp_jitter: float
    range_at_10: float
    range_at_80: float
    min_range: float
    range_sigma: float
    angle_sigma_deg: float
    beam_divergence_deg: tuple[float, float]
    max_return_probability: float
    fov_deg: tuple[float, ...]
    sky_noise_per_frame: float = 0.0
    sky_noise_range: tuple[float, float] = (0.0, 0.0)

    @property
    def origin(self) -> np.ndarray:
        return np.asarray(self.position, dtype=np.float64)

    @property
    def divergence_rad(self) -> float:
        """Mean full beam divergence (rad)."""
        return math.radians(sum(self.beam_divergence_deg) / 2)

    def rays_in_frame(self, frame_index: int) -> int:
        return self.rays_per_frame[frame_index % len(self.rays_per_frame)]

    def first_ray_index(self, frame_index: int) -> int:
        """Global index of the frame's first ray (rays counted since the sensor started)."""
        cycle = len(self.rays_per_frame)
        full, rest = divmod(frame_index, cycle)
        return full * sum(self.rays_per_frame) + sum(self.rays_per_frame[:rest])

    def scan(self, frame_index: int) -> tuple[np.ndarray, np.ndarray]:
        """Unit directions (N, 3) and firing times (N,) relative to the frame start."""
        dirs, times, _ = self.scan_angles(frame_index)
        return dirs, times

    def scan_angles(
        self, frame_index: int
    ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
        """Like :meth:`scan`, plus the rays' (azimuth, elevation) in radians."""
        n = self.rays_in_frame(frame_index)
        ray = np.arange(n)
        times = ray * (self.frame_period / n)
        g = self.first_ray_index(frame_index) + ray
        if self.sensor == MID360:
            az_span, el_min, el_max = (math.radians(v) for v in self.fov_deg)
            az = (2 * np.pi * ((ray / n + frame_index * SQRT2_FRAC) % 1.0)) - np.pi
            el = el_min + (el_max - el_min) * ((g * GOLDEN + 0.5) % 1.0)
            # float32 trigonometry is several times faster and exact to ~1e-7 rad.
            az32, el32 = az.astype(np.float32), el.astype(np.float32)
            cos_el = np.cos(el32)
            dirs = np.empty((n, 3))
            dirs[:, 0] = cos_el * np.cos(az32)
            dirs[:, 1] = cos_el * np.sin(az32)
            dirs[:, 2] = np.sin(el32)
            return dirs, times, (az, el)
        dirs, az, el = self._rosette(g, frame_index, times)
        return dirs, times, (az, el)

    def _rosette(
        self, g: np.ndarray, frame_index: int, times: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Directions, azimuth and elevation of the Risley-prism rosette for one frame.

        The prism rates differ by exactly ten turns per frame period, so over one period
        both prisms advance by the same fraction of a turn: frame k's pattern is frame
        0's rotated about the boresight by that fraction times k (0.1803 turn, an
        irrational-looking step, so the pattern never repeats). Frame 0 is cached.
        """
        u0 = self._rosette_cache(len(g), int(g[0]) % _LASERS)
        turn = (_PRISM_HZ[0] * self.frame_period * frame_index) % 1.0
        u = u0 * np.exp(2j * np.pi * turn)
        n = len(u)
        h_fov, v_fov = (math.radians(v) / 2 for v in self.fov_deg)
        ax = u.real * h_fov
        ay = u.imag * v_fov
        theta = np.hypot(ax, ay)
        theta32 = theta.astype(np.float32)
        scale = np.sin(theta32) / np.maximum(theta32, 1e-12)
        dirs = np.empty((n, 3))
        dirs[:, 0] = scale * ax
        dirs[:, 1] = scale * ay
        dirs[:, 2] = np.cos(theta32)
        return dirs, np.arctan2(ay, ax), np.pi / 2 - theta

    def _rosette_cache(self, n: int, first_laser: int) -> np.ndarray:
        key = (self.sensor, self.fov_deg, n, first_laser)
        u0 = _ROSETTE_CACHE.get(key)
        if u0 is None:
            times = np.arange(n) * (self.frame_period / n)
            laser = (first_laser + np.arange(n)) % _LASERS
            phase = laser * (2 * np.pi / _LASERS) * 0.05
            e1 = np.exp(1j * (2 * np.pi * _PRISM_HZ[0] * times + phase))
            e2 = np.exp(1j * (2 * np.pi * _PRISM_HZ[1] * times - phase))
            # Lasers sit on a short line across the scan, ~0.4 deg apart.
            u0 = 0.5 * (e1 + e2) + 1j * (laser - 2.5) * 0.01
            _ROSETTE_CACHE[key] = u0
        return u0

    def detection_range(self, reflectivity: np.ndarray) -> np.ndarray:
        """Range (m) at which a target of this reflectivity is detected half the time."""
        k = math.log(self.range_at_80 / self.range_at_10) / math.log(8.0)
        return self.range_at_10 * (np.maximum(reflectivity, 1e-4) / 0.1) ** k

    def footprint_area(self, distance: np.ndarray) -> np.ndarray:
        """Beam footprint area (m^2) at a distance (elliptical spot plus a 1 cm exit aperture)."""
        h, v = (math.radians(x) for x in self.beam_divergence_deg)
        return np.pi / 4 * (0.01 + distance * h) * (0.01 + distance * v)

    def return_probability(
        self,
        distance: np.ndarray,
        reflectivity: np.ndarray,
        cos_incidence: np.ndarray,
        cross_area: np.ndarray,
    ) -> np.ndarray:
        """Probability that a ray meeting a surface produces a point."""
        coverage = np.where(
            cross_area > 0, np.minimum(1.0, cross_area / self.footprint_area(distance)), 1.0
        )
        rho = reflectivity * np.clip(cos_incidence, 0.02, 1.0) * coverage
        r50 = self.detection_range(rho)
        z = np.clip((distance - r50) / (0.12 * r50), -50, 50)
        return self.max_return_probability / (1.0 + np.exp(z))


def mid360(position: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> LidarModel:
    """Livox Mid-360 as mounted on the MMAUD rig (sources in docs/simulator.md)."""
    return LidarModel(
        sensor=MID360,
        position=position,
        rays_per_frame=(19968, 20064),
        frame_period=0.1,
        stamp_offset=0.0,
        stamp_jitter=0.0005,
        range_at_10=40.0,
        range_at_80=70.0,
        min_range=0.1,
        range_sigma=0.02,
        angle_sigma_deg=0.05,
        beam_divergence_deg=(0.2, 0.2),
        max_return_probability=0.98,
        fov_deg=(360.0, -7.0, 52.0),
    )


def avia(position: tuple[float, float, float] = (0.05, 0.25, 0.12)) -> LidarModel:
    """Livox Avia pointing at the zenith as on the MMAUD rig (sources in docs/simulator.md)."""
    return LidarModel(
        sensor=AVIA,
        position=position,
        rays_per_frame=(24000,),
        frame_period=0.1,
        stamp_offset=0.0037,
        stamp_jitter=0.0005,
        range_at_10=190.0,
        range_at_80=320.0,
        min_range=1.0,
        range_sigma=0.02,
        angle_sigma_deg=0.05,
        beam_divergence_deg=(0.28, 0.03),
        max_return_probability=0.98,
        fov_deg=(70.4, 77.2),
        sky_noise_per_frame=4.0,
        sky_noise_range=(15.0, 420.0),
    )
