"""A known 3D shape photographed by a pinhole camera: the ground truth for tests and benchmarks/quality.py.

The shapes are a capsule (a cylinder with hemispherical caps) tilted in the
image plane, textured with coloured stripes along its axis, and the standing
solids (an upright cylinder, banded or in two plain colours, a box, a turned
box); sphere_hits intersects rays with a sphere analytically. Ray casting is sphere tracing of a shape's signed
distance, in float64 numpy.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from schemas.camera import pixel_rays
from schemas.images import write_image
from stages.reconstruct.geometry import intrinsics_from_fov, orbit_world_to_camera


def sphere_hits(rays: np.ndarray, centre: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Where unit rays t * rays (...,3) from the camera first meet the sphere about ``centre`` (3,) m of
    ``radius`` m: t (...) m, the nearer root (finite everywhere), and whether they meet it (...) bool."""
    along = rays @ centre
    reach = along ** 2 - (centre @ centre - radius ** 2)
    return along - np.sqrt(np.maximum(reach, 0)), reach > 0


@dataclass(frozen=True)
class Capsule:
    """Axis from ``centre - half_axis`` to ``centre + half_axis`` (metres), radius ``radius``."""

    centre: np.ndarray
    half_axis: np.ndarray
    radius: float

    @staticmethod
    def tilted(distance: float = 0.6, size_m: float = 0.25, radius: float = 0.05, tilt_deg: float = 20.0) -> "Capsule":
        """A capsule ``size_m`` long overall, ``distance`` in front of the camera, its axis turned in the
        image plane by ``tilt_deg``."""
        half = size_m / 2 - radius
        t = math.radians(tilt_deg)
        return Capsule(np.array([0.0, 0.0, distance]), half * np.array([math.cos(t), math.sin(t), 0.0]), radius)

    @property
    def size_m(self) -> float:
        """Largest extent: the overall length."""
        return 2 * (float(np.linalg.norm(self.half_axis)) + self.radius)

    @property
    def volume(self) -> float:
        """m^3: the cylinder and the two hemispheres."""
        r, length = self.radius, 2 * float(np.linalg.norm(self.half_axis))
        return math.pi * r * r * length + 4 / 3 * math.pi * r ** 3

    def principal_moments(self, density: float) -> np.ndarray:
        """Sorted principal moments of inertia (3,) kg m^2 of the solid capsule about its centre."""
        r, length = self.radius, 2 * float(np.linalg.norm(self.half_axis))
        cylinder, cap = density * math.pi * r * r * length, density * 2 / 3 * math.pi * r ** 3
        axial = cylinder * r * r / 2 + 2 * cap * 2 / 5 * r * r
        # each hemisphere about its own centre of mass (3/8 r from its flat face), moved to the capsule's
        across = cylinder * (length ** 2 / 12 + r * r / 4) + 2 * cap * (2 / 5 * r * r + length ** 2 / 4 + 3 * length * r / 8)
        return np.sort([axial, across, across])

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (...,) in metres of points (...,3): negative inside."""
        rel = points - self.centre
        axis_sq = self.half_axis @ self.half_axis
        s = np.clip((rel @ self.half_axis) / axis_sq, -1.0, 1.0)
        return np.linalg.norm(rel - s[..., None] * self.half_axis, axis=-1) - self.radius

    def color(self, points: np.ndarray) -> np.ndarray:
        """sRGB in [0,1] (...,3): stripes along the axis and a tint around it, so every view has texture."""
        rel = points - self.centre
        along = (rel @ self.half_axis) / (self.half_axis @ self.half_axis)
        stripes = 0.5 + 0.5 * np.sin(along * 3 * math.pi)
        around = 0.5 + 0.5 * rel[..., 1] / self.radius
        return np.stack([0.25 + 0.7 * stripes, 0.2 + 0.5 * np.clip(around, 0, 1), 0.8 - 0.6 * stripes], axis=-1)


@dataclass(frozen=True)
class Box:
    """An axis-aligned box ``centre`` +- ``half`` (metres, (3,) each), facing the camera, in two colours."""

    centre: np.ndarray
    half: np.ndarray

    @property
    def size_m(self) -> float:
        """Largest extent: the longest side."""
        return 2 * float(np.max(self.half))

    @property
    def volume(self) -> float:
        """m^3."""
        return 8 * float(np.prod(self.half))

    def principal_moments(self, density: float) -> np.ndarray:
        """Sorted principal moments of inertia (3,) kg m^2 of the solid box about its centre."""
        h, m = self.half, density * self.volume
        return np.sort([m / 3 * (h[1] ** 2 + h[2] ** 2), m / 3 * (h[0] ** 2 + h[2] ** 2), m / 3 * (h[0] ** 2 + h[1] ** 2)])

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (...,) in metres of points (...,3): negative inside."""
        q = np.abs(points - self.centre) - self.half
        return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(np.max(q, axis=-1), 0.0)

    def color(self, points: np.ndarray) -> np.ndarray:
        """sRGB in [0,1] (...,3): a checker of 2 cm squares, so every face has texture."""
        squares = np.nan_to_num((points - self.centre) / 0.02, posinf=0.0, neginf=0.0)  # rays that miss run far
        cells = np.floor(np.clip(squares, -1e9, 1e9)).astype(np.int64).sum(axis=-1) % 2
        return np.where(cells[..., None] == 0, [0.85, 0.45, 0.2], [0.3, 0.55, 0.8])


def standing_axes(pitch_deg: float, yaw_deg: float = 0.0) -> np.ndarray:
    """(3,3) rows: an upright body's own x, up and z axes in the frame of a camera pitched down by pitch_deg,
    the body turned by yaw_deg about the vertical."""
    p, y = math.radians(pitch_deg), math.radians(yaw_deg)
    right, up, away = np.array([1.0, 0, 0]), np.array([0.0, -math.cos(p), -math.sin(p)]), np.array([0.0, -math.sin(p), math.cos(p)])
    return np.stack([math.cos(y) * right + math.sin(y) * away, up, -math.sin(y) * right + math.cos(y) * away])


@dataclass(frozen=True)
class UprightCylinder:
    """A cylinder standing on the ground: ``centre`` (3,) m its middle, ``axes`` (3,3) rows its own x, up, z
    (standing_axes), ``radius`` and ``height`` m."""

    centre: np.ndarray
    axes: np.ndarray
    radius: float
    height: float

    @property
    def size_m(self) -> float:
        """Largest extent: the longer of its diameter and its height."""
        return max(2 * self.radius, self.height)

    @property
    def volume(self) -> float:
        return math.pi * self.radius ** 2 * self.height

    def principal_moments(self, density: float) -> np.ndarray:
        m = density * self.volume
        across = m * (3 * self.radius ** 2 + self.height ** 2) / 12
        return np.sort([m * self.radius ** 2 / 2, across, across])

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        local = (points - self.centre) @ self.axes.T
        d = np.stack([np.hypot(local[..., 0], local[..., 2]) - self.radius, np.abs(local[..., 1]) - self.height / 2], -1)
        return np.linalg.norm(np.maximum(d, 0.0), axis=-1) + np.minimum(np.max(d, axis=-1), 0.0)

    def color(self, points: np.ndarray) -> np.ndarray:
        """Bands up its side and a tint around it."""
        local = (points - self.centre) @ self.axes.T
        bands = 0.5 + 0.5 * np.sin(local[..., 1] / self.height * 4 * math.pi)
        around = 0.5 + 0.5 * np.sin(np.arctan2(local[..., 2], local[..., 0]) * 3)
        return np.stack([0.2 + 0.7 * bands, 0.3 + 0.5 * around, 0.8 - 0.6 * bands], axis=-1)


@dataclass(frozen=True)
class PaintedCylinder(UprightCylinder):
    """An upright cylinder in two plain colours, as a cup seen from above: ``side`` (3,) sRGB in [0,1] on its
    side and base, ``top`` on its top face."""

    side: tuple = (0.75, 0.1, 0.08)
    top: tuple = (0.95, 0.95, 0.9)

    def on_top(self, points: np.ndarray) -> np.ndarray:
        """(...,) bool: the points nearer the top face than the side or the base."""
        local = (points - self.centre) @ self.axes.T
        to_top = np.abs(local[..., 1] - self.height / 2)
        return to_top < np.minimum(np.abs(np.hypot(local[..., 0], local[..., 2]) - self.radius),
                                   np.abs(local[..., 1] + self.height / 2))

    def color(self, points: np.ndarray) -> np.ndarray:
        return np.where(self.on_top(points)[..., None], self.top, self.side)


@dataclass(frozen=True)
class TurnedBox(Box):
    """A box standing on the ground, turned about the vertical: ``centre`` (3,) m, ``half`` (3,) m its half
    sides along its own axes, ``axes`` (3,3) rows its own x, up, z (standing_axes)."""

    axes: np.ndarray = field(default_factory=lambda: np.eye(3))

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        return Box(np.zeros(3), self.half).signed_distance((points - self.centre) @ self.axes.T)

    def color(self, points: np.ndarray) -> np.ndarray:
        return Box(np.zeros(3), self.half).color((points - self.centre) @ self.axes.T)


@dataclass
class Photograph:
    """What a camera sees of the capsule: RGB u8 (H,W,3) over a grey backdrop, mask (H,W) bool, and the
    distance along the ray (H,W) to the surface in metres (NaN off it)."""

    rgb: np.ndarray
    mask: np.ndarray
    distance: np.ndarray


Shape = Capsule | Box | UprightCylinder | PaintedCylinder | TurnedBox


def photograph(shape: Shape, K: np.ndarray, world_to_camera: np.ndarray, width: int, height: int,
               steps: int = 96) -> Photograph:
    """Ray-cast ``shape`` from the camera (pinhole, DESIGN.md conventions)."""
    rotation, translation = world_to_camera[:3, :3], world_to_camera[:3, 3]
    origin = -rotation.T @ translation
    directions = pixel_rays(K, height, width) @ rotation  # camera -> world: R^T d, row vectors
    t = np.zeros((height, width))
    for _ in range(steps):
        t += np.maximum(shape.signed_distance(origin + directions * t[..., None]), 0)
    points = origin + directions * t[..., None]
    hit = np.abs(shape.signed_distance(points)) < 1e-5
    rgb = np.where(hit[..., None], shape.color(points), 0.45)
    return Photograph((rgb * 255).round().astype(np.uint8), hit, np.where(hit, t, np.nan))


def write_scene(folder: Path, shape: Shape, fov_deg: float = 40.0, width: int = 256, height: int = 192,
                iterations: int = 600, pitch_deg: float = 0.0) -> Path:
    """A scene folder (scene.yaml, photo.png, mask.png) of ``shape`` seen by the input camera (the world frame,
    pitched down by pitch_deg); returns scene.yaml."""
    folder.mkdir(parents=True, exist_ok=True)
    photo = photograph(shape, intrinsics_from_fov(fov_deg, width, height), np.eye(4), width, height)
    write_image(folder / "photo.png", cv2.cvtColor(photo.rgb, cv2.COLOR_RGB2BGR))
    write_image(folder / "mask.png", photo.mask.astype(np.uint8) * 255)
    (folder / "scene.yaml").write_text(
        f"image: photo.png\ncamera: {{fov_deg: {fov_deg}, pitch_deg: {pitch_deg}}}\n"
        f"objects:\n  - mask: mask.png\n    size_m: {shape.size_m}\n"
        f"reconstruct: {{resolution: {max(width, height)}, iterations: {iterations}}}\n")
    return folder / "scene.yaml"


def side_view(shape: Capsule, azimuth_deg: float = 90.0) -> np.ndarray:
    """world_to_camera (4,4) of the input camera orbited about the capsule's centre."""
    return orbit_world_to_camera(shape.centre, azimuth_deg)


def soft_edged(photo: Photograph, backdrop: np.ndarray, blur_px: float, rim_px: float = 0.0,
               rim_rgb: tuple = (40, 40, 40)) -> tuple[np.ndarray, np.ndarray]:
    """``photo``'s object over ``backdrop`` (H, W, 3 u8, the known background) with its outline blurred, as a
    defocused or motion-blurred object is photographed: its colour and coverage blurred by a Gaussian of
    ``blur_px`` pixels and composited over the sharp backdrop (premultiplied). Its outermost ``rim_px``
    pixels may be a dark frame of ``rim_rgb``. Returns the photograph (H, W, 3 u8) and the object's blurred
    coverage (H, W float in [0, 1]) of all but that rim: where a segmentation that leaves the rim out ends."""
    inside = photo.mask.astype(np.uint8)
    colour = photo.rgb.astype(np.float64)
    depth = cv2.distanceTransform(inside, cv2.DIST_L2, 5)
    rim = photo.mask & (depth <= rim_px)
    colour[rim] = rim_rgb
    blur = lambda image: cv2.GaussianBlur(image, (0, 0), blur_px)  # noqa: E731
    coverage = blur(inside.astype(np.float64))
    premultiplied = blur(colour * inside[..., None])
    composite = premultiplied + (1 - coverage[..., None]) * backdrop.astype(np.float64)
    return np.clip(composite + 0.5, 0, 255).astype(np.uint8), blur((photo.mask & ~rim).astype(np.float64))
