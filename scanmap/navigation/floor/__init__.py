"""Floor segmentation and the obstacle layer: where the robot can drive, and what is in its way.

`segment` (`segmentation`) turns a window of the grid's cells (`CellLayers`) into a
`Segmentation` (`result`): each cell's floor height and slope, whether it is floor, and
its state, one of FREE, OBSTACLE, DROP_OFF and UNKNOWN, for a robot of a `RobotShape`
under a `FloorConfig` (`config`). Four stages, each a module whose docstring states its
rules:

* `_model`: the floor - candidates (a cell's thin lowest level), their slopes, the
  dominant plane's region grown over them across ramps and low sills but not up a step's
  face, the step's edges between two floors, and the floor heights carried into the
  cells without floor;
* `_drop_offs`: where the floor is missing - cells below the floor near them and where
  the robot stood, spread through the rim's shadow across the scanner's view;
* `_unseen`: no return is not free - the cells neither seen as floor nor known to be
  (stood on, a gap between the laser's samples, assumed) stay unknown;
* `_states`: each cell's state from what occupies the robot's band above its floor,
  then the rules that keep a cell beside a drop-off from being FREE on too little.

Kernels (Numba, `nogil`), one module per part: `_plane_kernels` (candidates, planes,
slopes), `_growth_kernels` (the floor's growth, a step's face and edges), `_seen_kernels`
(what the cells saw: below the floor, openings between samples) and `_band_kernels` (the
robot's band, overhangs).
"""

from scanmap.navigation._kernels import DROP_OFF, FREE, OBSTACLE, UNKNOWN
from scanmap.navigation.floor._model import ransac_plane
from scanmap.navigation.floor.config import FloorConfig, RobotShape
from scanmap.navigation.floor.result import FloorPlane, Segmentation
from scanmap.navigation.floor.segmentation import segment

__all__ = [
    "DROP_OFF",
    "FREE",
    "OBSTACLE",
    "UNKNOWN",
    "FloorConfig",
    "FloorPlane",
    "RobotShape",
    "Segmentation",
    "ransac_plane",
    "segment",
]
