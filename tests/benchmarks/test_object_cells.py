"""The cells the benchmarks' wall figures single out by how far an object reaches into them
(`bench_grid.object_cells`, `mixed_cells`), against boxes placed off the cell edges."""

from __future__ import annotations

import numpy as np

from benchmarks.bench_grid import mixed_cells, object_cells
from scanmap_driver.sim.raster import OBSTACLE, truth_raster
from scanmap_driver.sim.scene import Scene

GREY = [128, 128, 128]


def box(x0: float, x1: float, y0: float, y1: float) -> dict:
    return {"type": "box", "center": [(x0 + x1) / 2, (y0 + y1) / 2, 0.4],
            "size": [x1 - x0, y1 - y0, 0.8], "color": GREY}


# Faces cutting the cell column x in [2.0, 2.05): 5 mm, 30 mm and 1 mm into it; panels
# 2 cm and 1.5 cm thick at x = 3.0 and 3.5.
SCENE = Scene.from_dict({"format": "scanmap.scene/1", "floor": {"color": GREY},
                         "ambient": 1.0, "scan_poses": [[0.5, 0.5, 0.0]],
                         "objects": [box(2.045, 2.4, 0.0, 0.4), box(1.6, 2.03, 1.0, 1.4),
                                     box(2.049, 2.4, 2.0, 2.4), box(3.0, 3.02, 0.0, 1.0),
                                     box(3.5, 3.515, 0.0, 1.0)]})


def at(cells: np.ndarray, raster, x: float, y: float) -> bool:
    row, col = raster.cell_of(np.array([[x, y]]))[0]
    return bool(cells[row, col])


def test_shrunk_objects_keep_the_cells_they_reach_deep_into():
    raster = truth_raster(SCENE, 0.05, 0.05, 1.0)
    assert (object_cells(SCENE, raster, 0.0) == (raster.classes == OBSTACLE)).all()
    deep = object_cells(SCENE, raster, -0.01)
    assert not at(deep, raster, 2.025, 0.2)  # a 5 mm sliver
    assert at(deep, raster, 2.075, 0.2)
    assert at(deep, raster, 2.025, 1.2)  # 30 mm in
    assert not at(deep, raster, 2.075, 1.2)  # beyond the face
    # the panels, 2 cm and 1.5 cm thick, reach no more than 1 cm into any cell
    assert not deep[:, raster.cell_of(np.array([[2.95, 0.0]]))[0, 1]:].any()
    assert deep.sum() < (raster.classes == OBSTACLE).sum()


def test_a_face_within_2_mm_of_a_cell_edge_only_grazes_the_cell():
    raster = truth_raster(SCENE, 0.05, 0.05, 1.0)
    grazed = mixed_cells(SCENE, raster)
    assert at(grazed, raster, 2.025, 2.2)  # 1 mm
    assert not at(grazed, raster, 2.025, 0.2) and not at(grazed, raster, 2.025, 1.2)
