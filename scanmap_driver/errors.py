"""The one error hierarchy of scanmap (docs/architecture.md, "Errors and bad input").

Every error names the file or field at fault and what was expected, so a user can fix
the input without reading the code.
"""


class ScanmapError(Exception):
    """Root of every error scanmap raises on purpose."""


class CalibrationError(ScanmapError):
    """A scanner model or calibration is invalid, or the data cannot support one."""


class DeviceError(ScanmapError):
    """The camera or the motor controller failed; the motor has been stopped."""


class RecordingError(ScanmapError):
    """A raw recording is missing, malformed or corrupt."""


class ScanError(ScanmapError):
    """A scan (processed or being assembled) is malformed or incomplete."""


class SceneError(ScanmapError):
    """A simulator scene file is invalid."""


class RegistrationError(ScanmapError):
    """Registration failed (no overlap, divergence) and no pose is returned."""


class MapError(ScanmapError):
    """A map is invalid, corrupt, or a point lies outside its configured extent."""
