"""`preload_segmentation` loads every kernel the map's final segmentation needs."""

from __future__ import annotations

import subprocess
import sys

# In a fresh process (this one may have loaded the kernels already): two scans of a room,
# the preload, then the whole map's segmentation; prints the kernel specialisations the
# segmentation added (none when the preload loaded them all) and how many it found.
SCRIPT = """
import numba
from scanmap.grid import _kernels as grid_kernels
from scanmap.mapping import Mapper
from scanmap.mapping.warm_up import room_scan
from scanmap.navigation import _kernels, morphology
from scanmap.navigation.floor import _band_kernels, _growth_kernels, _plane_kernels, _seen_kernels
from scanmap.pipelines.offline import OFFLINE_CONFIG, preload_segmentation
from scanmap_driver import reference_scanner

mapper = Mapper(reference_scanner(), OFFLINE_CONFIG, offline=True)
for index, shift in enumerate((0.0, 0.05)):
    mapper.add(room_scan(shift, index))
{preload}
modules = (_kernels, morphology, grid_kernels, _band_kernels, _growth_kernels, _plane_kernels,
           _seen_kernels)
kernels = [k for module in modules for k in vars(module).values()
           if isinstance(k, numba.core.registry.CPUDispatcher)]
before = {{k: len(k.overloads) for k in kernels}}
mapper.segment()
print(sum(len(k.overloads) - before[k] for k in kernels), sum(before.values()))
"""


def added_by_segmentation(preload: str) -> list[int]:
    result = subprocess.run([sys.executable, "-c", SCRIPT.format(preload=preload)],
                            capture_output=True, text=True, check=True)
    return [int(n) for n in result.stdout.split()]


def test_after_the_preload_the_segmentation_loads_no_kernel():
    added, loaded = added_by_segmentation("preload_segmentation(mapper).join()")
    assert added == 0 and loaded >= 15
    added, _ = added_by_segmentation("")  # the measure can tell: without it, it loads them
    assert added >= 15


def test_without_a_pose_nothing_is_preloaded():
    from scanmap.mapping import Mapper
    from scanmap.pipelines.offline import OFFLINE_CONFIG, preload_segmentation
    from scanmap_driver import reference_scanner

    assert preload_segmentation(Mapper(reference_scanner(), OFFLINE_CONFIG, offline=True)) \
        is None
