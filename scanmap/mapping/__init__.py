"""The Mapper: registers each scan, fuses it into the grid and publishes the obstacle
field; its configuration (`config`), its saved state (`state_file`), the background
mapping thread, kernel warm-up and per-frame scan motion. See docs/architecture.md."""

from scanmap.mapping.config import MapperConfig
from scanmap.mapping.mapper import Mapper, MapUpdate
from scanmap.mapping.state_file import MapperState, load_state, save_state
from scanmap.mapping.thread import MappingThread

__all__ = ["MapUpdate", "Mapper", "MapperConfig", "MapperState", "MappingThread",
           "load_state", "save_state"]
