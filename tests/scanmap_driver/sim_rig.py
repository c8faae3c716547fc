"""A scanner rig for tests: the simulated firmware on a pty, a camera rendering the true
head angle, and a heading decoder / assembler that read it back.

The frames carry the true angle at their exposure time in their pixels (8 bytes of a
float64, JPEG off), so the loop's plumbing (which heading went with which frame, when the
sweep ended, where the head stopped) is checked against the motor model's ground truth.
The assembler puts each frame's points on a cylindrical wall along its heading.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from scanmap_driver.camera import CameraFrame, RenderedCamera
from scanmap_driver.motor import MotorController
from scanmap_driver.scan import Scan
from scanmap_driver.scanner import ScanConfig, Scanner
from scanmap_driver.sim.firmware import SimulatedFirmware
from scanmap_driver.sim.motor_model import MotorModelConfig

WALL_RADIUS = 2.0
WALL_HEIGHTS = np.array([0.2, 0.5, 0.8])


def angle_image(angle: float) -> np.ndarray:
    """A tiny BGR image whose first 8 bytes are the float64 angle."""
    image = np.zeros((2, 4, 3), np.uint8)
    image.reshape(-1)[:8] = np.frombuffer(np.float64(angle).tobytes(), np.uint8)
    return image


def image_angle(image: np.ndarray) -> float:
    """The heading (rad, wrapped to [0, 2 pi)) written by `angle_image`."""
    angle = float(np.frombuffer(image.reshape(-1)[:8].tobytes(), np.float64)[0])
    return angle % (2.0 * math.pi)


def read_angle(frame: CameraFrame) -> float:
    """The heading decoder of the rig."""
    return image_angle(frame.image)


class WallAssembler:
    """Points on a cylindrical wall around the scanner, one column per frame at its heading."""

    def __init__(self) -> None:
        self.times: list[float] = []
        self.headings: list[float] = []

    def add_frame(self, image: np.ndarray, timestamp: float) -> float:
        self.times.append(timestamp)
        self.headings.append(image_angle(image))
        return self.headings[-1]

    def finish(self, index: int = 0, odom_start=None, odom_end=None) -> tuple[Scan, int]:
        n = WALL_HEIGHTS.size
        heading = np.repeat(self.headings, n)
        points = np.column_stack([WALL_RADIUS * np.cos(heading), WALL_RADIUS * np.sin(heading),
                                  np.tile(WALL_HEIGHTS, len(self.headings))])
        nan_pose = np.full((4, 4), np.nan)
        scan = Scan(points=points, colors=np.full((points.shape[0], 3), 200), heading=heading,
                    time=np.repeat(self.times, n), range_sigma=np.full(points.shape[0], 0.01),
                    frame_index=np.repeat(np.arange(len(self.times)), n), index=index,
                    stamp=self.times[0],
                    odom_start=nan_pose if odom_start is None else odom_start,
                    odom_end=nan_pose if odom_end is None else odom_end)
        return scan, len(self.times)


@dataclass
class Rig:
    firmware: SimulatedFirmware
    camera: RenderedCamera
    motor: MotorController
    scanner: Scanner


@contextlib.contextmanager
def rig(settings: ScanConfig | None = None, motor: MotorModelConfig | None = None,
        start_angle: float = 0.3, camera_type: type[RenderedCamera] = RenderedCamera,
        **scanner_options) -> Iterator[Rig]:
    """Firmware, camera, motor client and scanner, all closed at the end."""
    with SimulatedFirmware(motor, start_angle=start_angle) as firmware:
        camera = camera_type(lambda t: angle_image(firmware.angle_at(t)), jpeg_quality=None)
        controller = MotorController.connect(firmware.port)
        scanner = Scanner(camera, controller, read_angle, WallAssembler, settings,
                          **scanner_options)
        try:
            yield Rig(firmware, camera, controller, scanner)
        finally:
            camera.close()  # first: a frozen camera would hold up the scanner's grabber
            scanner.close()
            controller.close()
