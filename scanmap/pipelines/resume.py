"""A batch job continuing a saved map (`scanmap map --resume`): where its scans start in
the map, and what becomes of scans that could not be placed in it."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scanmap.graph.localise import NotLocalised
from scanmap.mapping.mapper import Mapper, MapUpdate
from scanmap_driver.scan import Scan
from scanmap_driver.transforms import pose_to_se2


@dataclass(frozen=True)
class Resume:
    """A map.npz to continue. localise: the robot may have been moved since the map was
    saved, so its scans are located in it first (`Mapper.load(localise=True)`), near
    `hint` (4x4 pose in the map) when given; the report notes the scans it took."""

    path: Path
    localise: bool = False
    hint: np.ndarray | None = None

    @classmethod
    def of(cls, resume: Resume | str | os.PathLike[str] | None) -> Resume | None:
        """`resume` as a Resume (a plain path continues where the robot stopped)."""
        return resume if resume is None or isinstance(resume, Resume) else cls(Path(resume))

    def mapper(self) -> Mapper:
        """The saved map's Mapper, offline."""
        return Mapper.load(self.path, offline=True, localise=self.localise, hint=self.hint)


def add_located(mapper: Mapper, scan: Scan, notes: list[str]) -> MapUpdate | None:
    """`mapper.add(scan)`, or None with a note while the session is not yet located in the
    map (the Mapper keeps the scan and maps it once it is)."""
    try:
        return mapper.add(scan)
    except NotLocalised as exc:
        notes.append(f"scan {scan.index}: {exc}")
        return None


def localisation_summary(mapper: Mapper, notes: list[str]) -> dict | None:
    """Where the first scan was located in a resumed map (None when not asked to); raises
    NotLocalised, with the last scan's reason, when no scan was."""
    if mapper.localising:
        raise NotLocalised(notes[-1] if notes else "no scan to locate in the map")
    found = mapper.localisation
    if found is None:
        return None
    x, y, yaw = pose_to_se2(found.pose)
    return {"x": x, "y": y, "yaw": yaw, "found_by": found.found_by, "node": found.node,
            "fitness": found.fitness, "inlier_rmse": found.inlier_rmse}


def localisation_text(localised: dict) -> str:
    """One line for people: where the first scan was located in the resumed map."""
    return (f"located in the map at ({localised['x']:.2f}, {localised['y']:.2f}) m, "
            f"{np.degrees(localised['yaw']):.1f} deg, by {localised['found_by']} "
            f"(keyframe {localised['node']}, {100 * localised['fitness']:.0f}% of the points "
            f"matched, {100 * localised['inlier_rmse']:.1f} cm RMS)")
