"""LGM's cameras and their Pluecker ray embeddings.

LGM's object frame is OpenGL's: x right, y up, z towards the camera of view 0.
Its four input cameras orbit the origin at ``CAMERA_RADIUS`` at elevation 0 and
azimuths 0, 90, 180, 270 degrees (azimuth 0 on +z, 90 on +x), look at the
origin with y up, and have a vertical field of view of ``FOVY_DEG``. A camera's
own axes are OpenGL's too: it looks along its -z.

The embedding of pixel (row i, col j) of a view is (o x d, d): o the camera
centre, d the unit direction of the ray through the pixel centre (j + 0.5, i + 0.5),
both in the object frame. A point p lies on that ray's line exactly when
p x d = o x d.
"""
from __future__ import annotations

import math

import numpy as np
import torch

FOVY_DEG = 49.1
CAMERA_RADIUS = 1.5
ELEVATION_DEG = 0.0
AZIMUTHS_DEG = (0.0, 90.0, 180.0, 270.0)


def orbit_pose(elevation_deg: float, azimuth_deg: float, radius: float = CAMERA_RADIUS) -> np.ndarray:
    """camera_to_world (4,4) float64 of an OpenGL camera on the orbit, looking at the origin, y up.

    Elevation is positive above the equator (the camera's y position is radius sin(elevation))."""
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    centre = radius * np.array([math.cos(e) * math.sin(a), math.sin(e), math.cos(e) * math.cos(a)])
    backward = centre / np.linalg.norm(centre)  # the camera's +z points away from what it sees
    right = np.cross([0.0, 1.0, 0.0], backward)
    right /= np.linalg.norm(right)
    up = np.cross(backward, right)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([right, up, backward], axis=1)
    pose[:3, 3] = centre
    return pose


def view_poses(elevation_deg: float = ELEVATION_DEG, azimuths_deg=AZIMUTHS_DEG) -> np.ndarray:
    """camera_to_world (V,4,4) of LGM's input views."""
    return np.stack([orbit_pose(elevation_deg, a) for a in azimuths_deg])


def focal_px(size: int, fovy_deg: float = FOVY_DEG) -> float:
    """Focal length in pixels of a square view ``size`` pixels high."""
    return 0.5 * size / math.tan(math.radians(fovy_deg) / 2)


def view_rays(pose: np.ndarray, size: int, fovy_deg: float = FOVY_DEG) -> tuple[np.ndarray, np.ndarray]:
    """Ray origins and unit directions (size,size,3) each, object frame, through the pixel centres of a
    square view with camera_to_world ``pose`` (4,4)."""
    focal = focal_px(size, fovy_deg)
    centre = np.arange(size) + 0.5 - size / 2
    x, y = np.meshgrid(centre / focal, centre / focal)  # x along columns, y down the rows
    camera = np.stack([x, -y, -np.ones_like(x)], axis=-1)  # OpenGL: image rows go down, y goes up
    directions = camera @ pose[:3, :3].T
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    return np.broadcast_to(pose[:3, 3], directions.shape).copy(), directions


def plucker_embedding(poses: np.ndarray, size: int, fovy_deg: float = FOVY_DEG) -> torch.Tensor:
    """The (V,6,size,size) float32 Pluecker embedding (o x d, d) of views with camera_to_world ``poses``."""
    planes = []
    for pose in poses:
        origins, directions = view_rays(pose, size, fovy_deg)
        planes.append(np.concatenate([np.cross(origins, directions), directions], axis=-1))
    return torch.from_numpy(np.stack(planes).transpose(0, 3, 1, 2).astype(np.float32)).contiguous()
