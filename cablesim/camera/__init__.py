"""Cameras: one interface for simulated, real and replayed RGB-D cameras."""

from cablesim.camera.base import Camera, CameraImage

__all__ = ["Camera", "CameraImage"]
