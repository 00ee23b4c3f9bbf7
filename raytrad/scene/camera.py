"""A pinhole camera: where an image is seen from (scene files, ``raytrad render --image``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from raytrad.constants import FLOAT32_MAX, defaults, tol
from raytrad.errors import SettingsError


@dataclass(frozen=True)
class Camera:
    """A pinhole camera.

    Attributes
    ----------
    position : (3,) float [m]
    look_at : (3,) float [m]
    up : (3,) float
    vertical_fov_deg : float [degrees]
    """

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    vertical_fov_deg: float = defaults.vertical_fov_deg

    def __post_init__(self) -> None:
        points = np.array([self.position, self.look_at, self.up], dtype=np.float64)
        if not (np.isfinite(points).all() and np.abs(points).max() <= FLOAT32_MAX):
            raise SettingsError(
                "camera position, look_at and up must be finite numbers within float32 range"
            )
        forward = np.subtract(self.look_at, self.position)
        length = float(np.linalg.norm(forward))
        # rounding far from the origin: look_at must differ from position by more than
        # the float64 resolution of their coordinates
        reach = float(np.abs(np.concatenate([self.position, self.look_at])).max(initial=0.0))
        if not np.isfinite(forward).all() or length <= tol.collinear * reach or length == 0:
            raise SettingsError("camera position and look_at must differ")
        up = float(np.linalg.norm(self.up))
        if np.linalg.norm(np.cross(forward, self.up)) <= tol.parallel * length * up:
            raise SettingsError("camera up must not be parallel to the view direction")
        if not 0 < self.vertical_fov_deg < 180:
            raise SettingsError(
                f"vertical field of view must be in (0, 180), got {self.vertical_fov_deg}"
            )

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(right, up, forward) orthonormal vectors of the camera frame."""
        forward = np.subtract(self.look_at, self.position).astype(np.float64)
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, self.up)
        right /= np.linalg.norm(right)
        return right, np.cross(right, forward), forward


@dataclass(frozen=True)
class NamedCamera:
    """A camera a scene file names (a glTF camera node, a TOML ``[camera]``).

    Attributes
    ----------
    name : str
        glTF: the node's name, else the camera's, else ``"camera <i>"`` (``i`` the camera
        index); TOML: ``"camera"``.
    camera : Camera
        Position [m], ``look_at`` one metre along the view direction [m], unit up vector,
        vertical field of view [degrees].
    aspect_ratio : float or None
        Width over height [1] the file asks for, or None if it leaves it to the viewport.
    """

    name: str
    camera: Camera
    aspect_ratio: float | None = None
