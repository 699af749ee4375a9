"""setup.png: what pm-simulate is about to do, drawn over the photograph.

Each object's particles as dots in its own colour, the ground as a grid of
lines on its plane, the gravity-aligned axes the conditions are written in
(x, y down, z), every condition's region (its particles, highlighted) and
arrows for impulses, velocities, forces (direction) and torques (axis).
"""
from __future__ import annotations

import cv2
import numpy as np

from schemas.camera import project_points

OBJECT_COLOURS = [(80, 200, 255), (255, 160, 60), (120, 255, 120), (255, 90, 200), (200, 200, 200)]  # BGR
CONDITION_COLOUR = {"impulse": (0, 0, 255), "velocity": (0, 140, 255), "force": (255, 0, 255),
                    "torque": (255, 255, 0), "fixed": (60, 60, 60)}


def _project(K: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Pixel coordinates (N,2) of world points (N,3) in the input camera (world = camera frame)."""
    return project_points(points, K)


def _pt(p) -> tuple[int, int]:
    return int(round(float(p[0]))), int(round(float(p[1])))


def draw_setup(sim, photo: np.ndarray, K: np.ndarray) -> np.ndarray:
    """The setup image (H,W,3) BGR u8 of a `simulation.Simulation` over the photograph (RGB u8)."""
    img = cv2.cvtColor(photo, cv2.COLOR_RGB2BGR) // 2
    x, obj = sim.rest_world, sim.object_id
    size = float(np.max(x.max(0) - x.min(0)))
    if sim.physics.ground.enabled:
        # a square of grid lines on the ground plane under the objects, 3 object sizes wide
        e1, e3 = sim.Q[0], sim.Q[2]  # in-plane world directions
        up = sim.Q[1]
        centre = x.mean(0) - up * (np.dot(x.mean(0), up) - np.min(x @ up))
        ticks = np.linspace(-1.5 * size, 1.5 * size, 7)
        for a in ticks:
            for d1, d2 in ((e1, e3), (e3, e1)):
                line = centre + np.outer(ticks, d2) + a * d1
                if np.all(line[:, 2] > 1e-3):
                    cv2.polylines(img, [np.round(_project(K, line)).astype(np.int32)], False, (90, 160, 90), 1,
                                  cv2.LINE_AA)
    step = max(1, len(x) // 20000)
    for p, k in zip(_project(K, x[::step]), obj[::step]):
        cv2.circle(img, _pt(p), 1, OBJECT_COLOURS[k % len(OBJECT_COLOURS)], -1)
    for i, item in enumerate(sim.conditions.items):
        c = item.condition
        colour = CONDITION_COLOUR[c.type]
        if c.region != "all":  # a whole object is already drawn
            for p in _project(K, x[item.members[:: max(1, len(item.members) // 5000)]]):
                cv2.circle(img, _pt(p), 1, colour, -1)
        m = sim.masses[item.members]
        centre = m @ x[item.members] / m.sum()
        vector = {"impulse": "velocity", "velocity": "velocity", "force": "force", "torque": "torque"}.get(c.type)
        start = _project(K, centre[None])[0]
        if vector is not None and np.linalg.norm(getattr(c, vector)) > 0:
            d = np.asarray(getattr(c, vector), float)
            tip = _project(K, (centre + 0.6 * size * d / np.linalg.norm(d))[None])[0]
            cv2.arrowedLine(img, _pt(start), _pt(tip), colour, 2, cv2.LINE_AA, tipLength=0.2)
        label = f"{i}:{c.type}" + (f" {c.start_s:g}s" if hasattr(c, "start_s") else "")
        cv2.putText(img, label, _pt(start + np.array([4.0, -4.0])), cv2.FONT_HERSHEY_SIMPLEX, 0.4, colour, 1,
                    cv2.LINE_AA)
    _draw_axes(img, K, sim.gravity_frame, x.mean(0), 0.35 * size)
    for k, m in enumerate(sim.materials):
        cv2.putText(img, f"object {k}: {m.preset}", (8, 16 + 16 * k), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                    OBJECT_COLOURS[k % len(OBJECT_COLOURS)], 1, cv2.LINE_AA)
    return img


AXIS_COLOURS = ((60, 60, 255), (60, 220, 60), (255, 140, 40))  # BGR: x red, y green, z blue


def _draw_axes(img: np.ndarray, K: np.ndarray, frame: np.ndarray, origin: np.ndarray, length: float) -> None:
    """The axes (rows of `frame`, world directions) from world point `origin`, `length` m long, labelled."""
    start = _project(K, origin[None])[0]
    for axis, name, colour in zip(frame, ("x", "y (down)", "z"), AXIS_COLOURS):
        tip = _project(K, (origin + length * axis)[None])[0]
        cv2.arrowedLine(img, _pt(start), _pt(tip), colour, 1, cv2.LINE_AA, tipLength=0.15)
        cv2.putText(img, name, _pt(tip + np.array([3.0, 3.0])), cv2.FONT_HERSHEY_SIMPLEX, 0.4, colour, 1,
                    cv2.LINE_AA)
