"""Errors the twin raises on bad input; the command line prints them without a traceback."""


class TwinError(Exception):
    """Base class: a problem with the user's input or configuration, stated in words."""


class DataFormatError(TwinError):
    """An input file is not in the I-24 MOTION layout (or is truncated)."""


class StoreError(TwinError):
    """A trajectory store is missing, incomplete or of an unknown format."""


class NoVehicleNearError(TwinError):
    """No recorded vehicle lies within the tolerance of a requested lane, position and time."""


class MapError(TwinError):
    """A map source file or a built map is missing, malformed or inconsistent."""


class ControllerError(TwinError):
    """A user's ego controller failed or returned something that is not a command."""
