"""The exceptions psrestir raises: one base class, a subclass by kind.

Every error of the native library arrives as one of these; a panic inside it arrives as
:class:`PsrestirError` ("internal error"), never as a crash of the interpreter.
"""


class PsrestirError(Exception):
    """Base class of every psrestir error."""


class FileError(PsrestirError, OSError):
    """A scene, image or task file is unreadable or invalid. ``path`` names it."""

    def __init__(self, message, path=None):
        PsrestirError.__init__(self, message)
        self.path = path

    def __str__(self):
        return str(self.args[0])


class InvalidArgument(PsrestirError, ValueError):
    """An argument is out of range, of the wrong shape or dtype, or used out of order
    (``backward`` without a ``render`` at the current textures)."""


class AdapterError(PsrestirError):
    """No GPU adapter (or CPU Vulkan driver) was found, or the one found lacks a feature or
    limit psrestir needs."""


class GpuOutOfMemory(PsrestirError, MemoryError):
    """The GPU ran out of memory."""


class DeviceLost(PsrestirError):
    """The GPU device was lost (driver reset, GPU removed); nothing more can run on it in
    this process."""


class GpuError(PsrestirError):
    """A GPU operation failed (a validation or driver error: a bug to report)."""


__all__ = [
    "PsrestirError",
    "FileError",
    "InvalidArgument",
    "AdapterError",
    "GpuOutOfMemory",
    "DeviceLost",
    "GpuError",
]
